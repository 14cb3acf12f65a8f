//! Small self-contained plots written as PNG: line plots (axes, ticks, tick
//! labels, axis titles, a legend, several series) and a raster [`Image`] for
//! pictures such as the drapemeter's top view.
//!
//! Text uses the public-domain 8×8 bitmap font of the `font8x8` crate (ASCII,
//! Latin-1 and Greek: `°`, `·`, `²`, `θ`, `κ`… are available), so nothing
//! depends on the fonts installed on the machine.
//!
//! ```no_run
//! use garment_sim::pictures::plot::{LinePlot, Style};
//! let mut p = LinePlot::new("Tensile, warp", "strain (%)", "force (gf/cm)");
//! p.add("input curve", vec![(0.0, 0.0), (5.0, 500.0)], Style::Line);
//! p.add("simulated", vec![(0.0, 0.0), (5.1, 500.0)], Style::Dashed);
//! p.save_png(std::path::Path::new("out/plot.png")).unwrap();
//! ```

use anyhow::{Context, Result};
use font8x8::UnicodeFonts;
use std::path::Path;

/// An RGB colour.
pub type Rgb = [u8; 3];

pub const WHITE: Rgb = [255, 255, 255];
pub const BLACK: Rgb = [0, 0, 0];
pub const GREY: Rgb = [200, 200, 200];
pub const LIGHT_GREY: Rgb = [235, 235, 235];

/// Colours given to series in order (colour-blind safe, Okabe–Ito).
pub const PALETTE: [Rgb; 8] = [
    [0, 0, 0],
    [213, 94, 0],
    [0, 114, 178],
    [0, 158, 115],
    [204, 121, 167],
    [230, 159, 0],
    [86, 180, 233],
    [240, 228, 66],
];

/// An RGB raster image.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    /// Row-major pixels, top row first.
    pub pixels: Vec<Rgb>,
}

impl Image {
    pub fn new(width: usize, height: usize, background: Rgb) -> Image {
        Image {
            width,
            height,
            pixels: vec![background; width * height],
        }
    }

    /// Sets a pixel; coordinates outside the image are ignored.
    #[inline]
    pub fn set(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = c;
        }
    }

    pub fn get(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }

    pub fn fill_rect(&mut self, x0: i64, y0: i64, w: i64, h: i64, c: Rgb) {
        for y in y0..y0 + h {
            for x in x0..x0 + w {
                self.set(x, y, c);
            }
        }
    }

    /// A straight line `thickness` pixels wide (Bresenham with a square pen).
    pub fn line(&mut self, p0: (f64, f64), p1: (f64, f64), c: Rgb, thickness: i64) {
        let (mut x0, mut y0) = (p0.0.round() as i64, p0.1.round() as i64);
        let (x1, y1) = (p1.0.round() as i64, p1.1.round() as i64);
        let dx = (x1 - x0).abs();
        let dy = -(y1 - y0).abs();
        let sx = if x0 < x1 { 1 } else { -1 };
        let sy = if y0 < y1 { 1 } else { -1 };
        let mut err = dx + dy;
        let lo = -(thickness - 1) / 2;
        let hi = thickness / 2;
        // guard against absurd coordinates (a NaN or a huge value)
        let limit = 4 * (self.width + self.height) as i64;
        if x0.abs() > 100 * limit || y0.abs() > 100 * limit {
            return;
        }
        let mut n = 0;
        loop {
            for oy in lo..=hi {
                for ox in lo..=hi {
                    self.set(x0 + ox, y0 + oy, c);
                }
            }
            if (x0 == x1 && y0 == y1) || n > 100 * limit {
                break;
            }
            n += 1;
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x0 += sx;
            }
            if e2 <= dx {
                err += dx;
                y0 += sy;
            }
        }
    }

    /// Filled circle of radius `r` pixels.
    pub fn disc(&mut self, cx: f64, cy: f64, r: f64, c: Rgb) {
        let (x0, x1) = ((cx - r).floor() as i64, (cx + r).ceil() as i64);
        let (y0, y1) = ((cy - r).floor() as i64, (cy + r).ceil() as i64);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (dx, dy) = (x as f64 - cx, y as f64 - cy);
                if dx * dx + dy * dy <= r * r {
                    self.set(x, y, c);
                }
            }
        }
    }

    /// Circle outline of radius `r` pixels.
    pub fn circle(&mut self, cx: f64, cy: f64, r: f64, c: Rgb, thickness: i64) {
        let n = ((2.0 * std::f64::consts::PI * r) as usize).clamp(16, 20_000);
        let p = |k: usize| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            (cx + r * a.cos(), cy + r * a.sin())
        };
        for k in 0..n {
            self.line(p(k), p(k + 1), c, thickness);
        }
    }

    /// Fills a triangle given in pixel coordinates (centres of pixels inside).
    pub fn fill_triangle(&mut self, a: (f64, f64), b: (f64, f64), c: (f64, f64), col: Rgb) {
        let y0 = a.1.min(b.1).min(c.1).floor().max(0.0) as i64;
        let y1 = a.1.max(b.1).max(c.1).ceil().min(self.height as f64) as i64;
        let x0 = a.0.min(b.0).min(c.0).floor().max(0.0) as i64;
        let x1 = a.0.max(b.0).max(c.0).ceil().min(self.width as f64) as i64;
        let edge = |p: (f64, f64), q: (f64, f64), x: f64, y: f64| {
            (q.0 - p.0) * (y - p.1) - (q.1 - p.1) * (x - p.0)
        };
        let area = edge(a, b, c.0, c.1);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = edge(b, c, px, py) * area.signum();
                let w1 = edge(c, a, px, py) * area.signum();
                let w2 = edge(a, b, px, py) * area.signum();
                if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
                    self.set(x, y, col);
                }
            }
        }
    }

    /// Draws text with its top-left corner at (x, y); `scale` multiplies the
    /// 8×8 glyphs. Characters the font lacks are drawn as `?`.
    pub fn text(&mut self, x: i64, y: i64, s: &str, scale: i64, c: Rgb) {
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            let gx = x + k as i64 * 8 * scale;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        self.fill_rect(gx + col * scale, y + row as i64 * scale, scale, scale, c);
                    }
                }
            }
        }
    }

    /// Text rotated 90° counter-clockwise (reads bottom to top), its
    /// bottom-left corner at (x, y).
    pub fn text_vertical(&mut self, x: i64, y: i64, s: &str, scale: i64, c: Rgb) {
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            let gy = y - k as i64 * 8 * scale;
            for (row, bits) in g.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        // glyph (col, row) -> image (x + row, gy - col)
                        self.fill_rect(
                            x + row as i64 * scale,
                            gy - (col + 1) * scale,
                            scale,
                            scale,
                            c,
                        );
                    }
                }
            }
        }
    }

    /// Writes the image as an 8-bit RGB PNG (creating the parent directory).
    pub fn save_png(&self, path: &Path) -> Result<()> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create directory {}", dir.display()))?;
        }
        let f = std::fs::File::create(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let mut enc = png::Encoder::new(
            std::io::BufWriter::new(f),
            self.width as u32,
            self.height as u32,
        );
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc
            .write_header()
            .with_context(|| format!("writing PNG header of {}", path.display()))?;
        let data: Vec<u8> = self.pixels.iter().flatten().copied().collect();
        w.write_image_data(&data)
            .with_context(|| format!("writing PNG data of {}", path.display()))?;
        Ok(())
    }
}

fn glyph(ch: char) -> [u8; 8] {
    font8x8::BASIC_FONTS
        .get(ch)
        .or_else(|| font8x8::LATIN_FONTS.get(ch))
        .or_else(|| font8x8::GREEK_FONTS.get(ch))
        .or_else(|| font8x8::BASIC_FONTS.get('?'))
        .unwrap_or([0; 8])
}

/// Width in pixels of a text at a scale.
pub fn text_width(s: &str, scale: i64) -> i64 {
    s.chars().count() as i64 * 8 * scale
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Solid line through the points in order.
    Line,
    /// Dashed line through the points in order.
    Dashed,
    /// A small disc at each point.
    Points,
}

/// One curve of a plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub color: Rgb,
    pub style: Style,
    /// Line width in pixels.
    pub width: i64,
}

/// A line plot: several series against shared axes.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Image size in pixels.
    pub size: (usize, usize),
    /// Axis ranges; `None` fits the data (with a margin, on nice ticks).
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Draw the x = 0 and y = 0 lines when they are inside the ranges.
    pub zero_lines: bool,
}

impl LinePlot {
    pub fn new(title: &str, x_label: &str, y_label: &str) -> LinePlot {
        LinePlot {
            title: title.to_string(),
            x_label: x_label.to_string(),
            y_label: y_label.to_string(),
            series: Vec::new(),
            size: (900, 600),
            x_range: None,
            y_range: None,
            zero_lines: true,
        }
    }

    /// Several curves sharing one x column (e.g. per-frame values against
    /// time): one solid line per `(label, ys)`, in palette order. Points
    /// where x or y is not finite are skipped (gaps).
    pub fn columns(
        title: &str,
        x_label: &str,
        y_label: &str,
        xs: &[f64],
        series: &[(&str, &[f64])],
    ) -> LinePlot {
        let mut p = LinePlot::new(title, x_label, y_label);
        for (label, ys) in series {
            let pts = xs
                .iter()
                .zip(ys.iter())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(&x, &y)| (x, y))
                .collect();
            p.add(label, pts, Style::Line);
        }
        p
    }

    /// Adds a series with the next palette colour.
    pub fn add(&mut self, label: &str, points: Vec<(f64, f64)>, style: Style) -> &mut Self {
        let color = PALETTE[self.series.len() % PALETTE.len()];
        self.add_colored(label, points, style, color)
    }

    pub fn add_colored(
        &mut self,
        label: &str,
        points: Vec<(f64, f64)>,
        style: Style,
        color: Rgb,
    ) -> &mut Self {
        self.series.push(Series {
            label: label.to_string(),
            points,
            color,
            style,
            width: 2,
        });
        self
    }

    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let fit = |sel: fn(&(f64, f64)) -> f64| {
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            for s in &self.series {
                for p in s
                    .points
                    .iter()
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                {
                    lo = lo.min(sel(p));
                    hi = hi.max(sel(p));
                }
            }
            if !lo.is_finite() {
                return (0.0, 1.0);
            }
            if hi - lo < 1e-300 {
                let d = if lo.abs() > 0.0 { lo.abs() * 0.1 } else { 1.0 };
                return (lo - d, hi + d);
            }
            let m = 0.04 * (hi - lo);
            (lo - m, hi + m)
        };
        (
            self.x_range.unwrap_or_else(|| fit(|p| p.0)),
            self.y_range.unwrap_or_else(|| fit(|p| p.1)),
        )
    }

    /// Renders the plot.
    pub fn render(&self) -> Image {
        let (w, h) = self.size;
        let mut img = Image::new(w, h, WHITE);
        let ((x0, x1), (y0, y1)) = self.ranges();
        let xt = nice_ticks(x0, x1, 8);
        let yt = nice_ticks(y0, y1, 8);
        let ylabels: Vec<String> = yt.iter().map(|&v| tick_label(v, &yt)).collect();
        let ylw = ylabels.iter().map(|s| text_width(s, 1)).max().unwrap_or(0);
        // plot area
        let left = 30 + ylw + 12;
        let right = w as i64 - 20;
        let top = 40;
        let bottom = h as i64 - 50;
        let px = |x: f64| left as f64 + (x - x0) / (x1 - x0) * (right - left) as f64;
        let py = |y: f64| bottom as f64 - (y - y0) / (y1 - y0) * (bottom - top) as f64;
        // grid and ticks
        for &t in xt.iter() {
            let x = px(t);
            img.line((x, top as f64), (x, bottom as f64), LIGHT_GREY, 1);
            img.line((x, bottom as f64), (x, bottom as f64 + 5.0), BLACK, 1);
            let s = tick_label(t, &xt);
            img.text(x as i64 - text_width(&s, 1) / 2, bottom + 9, &s, 1, BLACK);
        }
        for (t, s) in yt.iter().zip(&ylabels) {
            let y = py(*t);
            img.line((left as f64, y), (right as f64, y), LIGHT_GREY, 1);
            img.line((left as f64 - 5.0, y), (left as f64, y), BLACK, 1);
            img.text(left - 9 - text_width(s, 1), y as i64 - 4, s, 1, BLACK);
        }
        if self.zero_lines {
            if x0 < 0.0 && x1 > 0.0 {
                img.line((px(0.0), top as f64), (px(0.0), bottom as f64), GREY, 1);
            }
            if y0 < 0.0 && y1 > 0.0 {
                img.line((left as f64, py(0.0)), (right as f64, py(0.0)), GREY, 1);
            }
        }
        // series, clipped to the plot area
        for s in &self.series {
            let mut travelled = 0.0;
            for win in s.points.windows(2) {
                let (a, b) = ((px(win[0].0), py(win[0].1)), (px(win[1].0), py(win[1].1)));
                if !(a.0.is_finite() && a.1.is_finite() && b.0.is_finite() && b.1.is_finite()) {
                    continue;
                }
                let seg = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
                match s.style {
                    Style::Line => {
                        draw_clipped(&mut img, a, b, s.color, s.width, (left, top, right, bottom))
                    }
                    Style::Dashed => {
                        // 10 px on, 6 px off along the path
                        let n = (seg / 2.0).ceil().max(1.0) as usize;
                        for q in 0..n {
                            let t0 = q as f64 / n as f64;
                            let t1 = (q + 1) as f64 / n as f64;
                            let d = travelled + seg * t0;
                            if d % 16.0 < 10.0 {
                                let p0 = (a.0 + (b.0 - a.0) * t0, a.1 + (b.1 - a.1) * t0);
                                let p1 = (a.0 + (b.0 - a.0) * t1, a.1 + (b.1 - a.1) * t1);
                                draw_clipped(
                                    &mut img,
                                    p0,
                                    p1,
                                    s.color,
                                    s.width,
                                    (left, top, right, bottom),
                                );
                            }
                        }
                    }
                    Style::Points => {}
                }
                travelled += seg;
            }
            if s.style == Style::Points {
                for p in &s.points {
                    let (x, y) = (px(p.0), py(p.1));
                    if x >= left as f64
                        && x <= right as f64
                        && y >= top as f64
                        && y <= bottom as f64
                    {
                        img.disc(x, y, 1.0 + s.width as f64, s.color);
                    }
                }
            }
        }
        // frame
        img.line(
            (left as f64, top as f64),
            (right as f64, top as f64),
            BLACK,
            1,
        );
        img.line(
            (left as f64, bottom as f64),
            (right as f64, bottom as f64),
            BLACK,
            1,
        );
        img.line(
            (left as f64, top as f64),
            (left as f64, bottom as f64),
            BLACK,
            1,
        );
        img.line(
            (right as f64, top as f64),
            (right as f64, bottom as f64),
            BLACK,
            1,
        );
        // titles
        img.text(
            (left + right) / 2 - text_width(&self.title, 2) / 2,
            12,
            &self.title,
            2,
            BLACK,
        );
        img.text(
            (left + right) / 2 - text_width(&self.x_label, 1) / 2,
            bottom + 28,
            &self.x_label,
            1,
            BLACK,
        );
        img.text_vertical(
            8,
            (top + bottom) / 2 + text_width(&self.y_label, 1) / 2,
            &self.y_label,
            1,
            BLACK,
        );
        // legend (top left inside the plot area)
        if !self.series.is_empty() {
            let lw = self
                .series
                .iter()
                .map(|s| text_width(&s.label, 1))
                .max()
                .unwrap_or(0)
                + 50;
            let lh = 16 * self.series.len() as i64 + 8;
            let (lx, ly) = (left + 10, top + 10);
            img.fill_rect(lx, ly, lw, lh, WHITE);
            for (k, s) in self.series.iter().enumerate() {
                let y = (ly + 12 + 16 * k as i64) as f64;
                match s.style {
                    Style::Line => img.line(
                        (lx as f64 + 6.0, y),
                        (lx as f64 + 34.0, y),
                        s.color,
                        s.width,
                    ),
                    Style::Dashed => {
                        img.line(
                            (lx as f64 + 6.0, y),
                            (lx as f64 + 16.0, y),
                            s.color,
                            s.width,
                        );
                        img.line(
                            (lx as f64 + 24.0, y),
                            (lx as f64 + 34.0, y),
                            s.color,
                            s.width,
                        );
                    }
                    Style::Points => img.disc(lx as f64 + 20.0, y, 1.0 + s.width as f64, s.color),
                }
                img.text(lx + 42, y as i64 - 4, &s.label, 1, BLACK);
            }
            let (fx, fy) = (lx as f64, ly as f64);
            img.line((fx, fy), (fx + lw as f64, fy), GREY, 1);
            img.line(
                (fx, fy + lh as f64),
                (fx + lw as f64, fy + lh as f64),
                GREY,
                1,
            );
            img.line((fx, fy), (fx, fy + lh as f64), GREY, 1);
            img.line(
                (fx + lw as f64, fy),
                (fx + lw as f64, fy + lh as f64),
                GREY,
                1,
            );
        }
        img
    }

    pub fn save_png(&self, path: &Path) -> Result<()> {
        self.render().save_png(path)
    }
}

/// Draws the part of segment a–b inside the rectangle (Liang–Barsky).
fn draw_clipped(
    img: &mut Image,
    a: (f64, f64),
    b: (f64, f64),
    c: Rgb,
    width: i64,
    rect: (i64, i64, i64, i64),
) {
    let (l, t, r, btm) = (rect.0 as f64, rect.1 as f64, rect.2 as f64, rect.3 as f64);
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let mut u0: f64 = 0.0;
    let mut u1: f64 = 1.0;
    for (p, q) in [
        (-dx, a.0 - l),
        (dx, r - a.0),
        (-dy, a.1 - t),
        (dy, btm - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return;
            }
        } else {
            let u = q / p;
            if p < 0.0 {
                u0 = u0.max(u);
            } else {
                u1 = u1.min(u);
            }
        }
    }
    if u0 <= u1 {
        img.line(
            (a.0 + u0 * dx, a.1 + u0 * dy),
            (a.0 + u1 * dx, a.1 + u1 * dy),
            c,
            width,
        );
    }
}

/// Tick positions on "nice" values (1, 2, 5 × 10^k) covering [lo, hi] with at
/// most about `target` ticks.
pub fn nice_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| (hi - lo) / s <= target as f64 + 0.5)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// A tick label with as many decimals as the tick step needs.
fn tick_label(v: f64, ticks: &[f64]) -> String {
    let step = if ticks.len() >= 2 {
        (ticks[1] - ticks[0]).abs()
    } else {
        v.abs().max(1.0)
    };
    let big = ticks.iter().fold(0.0f64, |m, t| m.max(t.abs()));
    if big >= 1e5 || (big > 0.0 && big < 1e-3) {
        return format!("{v:.1e}");
    }
    let dec = if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    };
    let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
    format!("{v:.dec$}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice_and_cover() {
        assert_eq!(
            nice_ticks(0.0, 10.0, 5),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        let t = nice_ticks(-8.3, 8.3, 8);
        assert_eq!(t.first().copied(), Some(-8.0));
        assert_eq!(t.last().copied(), Some(8.0));
        assert_eq!(tick_label(0.5, &[0.0, 0.5, 1.0]), "0.5");
        assert_eq!(tick_label(-4.0, &[-4.0, -2.0]), "-4");
    }

    #[test]
    fn plot_draws_series_inside_axes() {
        let mut p = LinePlot::new("t", "x", "y");
        p.add_colored(
            "line",
            vec![(0.0, 0.0), (1.0, 1.0)],
            Style::Line,
            [255, 0, 0],
        );
        let img = p.render();
        let red = img.pixels.iter().filter(|&&c| c == [255, 0, 0]).count();
        // a diagonal across ~800 × 500 px at width 2, plus the legend swatch
        assert!(red > 800, "{red}");
        // text is drawn (black pixels well beyond the frame lines)
        let black = img.pixels.iter().filter(|&&c| c == BLACK).count();
        assert!(black > 3000, "{black}");
    }

    #[test]
    fn columns_make_one_series_per_column_and_save() {
        let t: Vec<f64> = (0..100).map(|k| k as f64 / 120.0).collect();
        let a: Vec<f64> = t.iter().map(|x| x.sin()).collect();
        let b: Vec<f64> = t
            .iter()
            .map(|x| if *x > 0.4 { f64::NAN } else { x.cos() })
            .collect();
        let p = LinePlot::columns("markers", "time (s)", "z (m)", &t, &[("a", &a), ("b", &b)]);
        assert_eq!(p.series.len(), 2);
        assert_eq!(p.series[0].points.len(), 100);
        assert!(p.series[1].points.len() < 100);
        assert_ne!(p.series[0].color, p.series[1].color);
        let path = std::env::temp_dir().join(format!("gs_plot_{}.png", std::process::id()));
        p.save_png(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn triangle_fill_covers_its_area() {
        let mut img = Image::new(100, 100, WHITE);
        img.fill_triangle((0.0, 0.0), (100.0, 0.0), (0.0, 100.0), BLACK);
        let n = img.pixels.iter().filter(|&&c| c == BLACK).count();
        assert!((n as f64 - 5000.0).abs() < 120.0, "{n}");
    }
}
