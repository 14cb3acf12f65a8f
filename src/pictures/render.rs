//! Pictures of a drape: a small software renderer (z-buffered triangle
//! rasteriser, Gouraud shading with a key and a fill light over an ambient
//! term, two-sided for the cloth) drawing on a [`plot::Image`].
//!
//! A [`Picture`] is one PNG: a large perspective view from the front left,
//! 30° above the horizontal, and orthographic top and front views, each
//! framed on the bounding box of the cloth and the obstacles. The cloth is
//! one colour (its underside a lighter shade), the obstacles grey; the top
//! view colours the cloth by strain, with a legend, when strains are given.
//! Labels give the scene, the grid and the time; the orthographic views
//! carry a scale bar in centimetres. Obstacles far larger than the cloth
//! (a floor) are framed only near the cloth.
//!
//! Conventions: world z is up; the front view looks along +y (x to the
//! right, z up); the top view looks down −z (x to the right, y up).

use crate::collision::Obstacle;
use crate::pictures::plot::{self, Image, Rgb};
use anyhow::Result;
use nalgebra::{Point3, Vector3};
use std::collections::HashMap;
use std::path::Path;

type V3 = Vector3<f64>;

/// A triangle mesh in world coordinates, m.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Surface {
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[usize; 3]>,
}

impl Surface {
    /// An obstacle where it is now: its triangulation
    /// ([`Obstacle::local_triangles`]) moved to its pose.
    pub fn from_obstacle(o: &Obstacle) -> Surface {
        let (v, t) = o.local_triangles();
        Surface {
            vertices: v
                .iter()
                .map(|p| {
                    let q = o.pose * Point3::new(p[0], p[1], p[2]);
                    [q.x, q.y, q.z]
                })
                .collect(),
            triangles: t
                .iter()
                .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
                .collect(),
        }
    }

    /// A triangle list (three points per triangle, as a TRIANGLE_LIST
    /// marker holds them), points at the same position merged into one vertex.
    pub fn from_triangle_list(points: &[[f64; 3]]) -> Surface {
        let mut index: HashMap<[u64; 3], usize> = HashMap::new();
        let mut vertices = Vec::new();
        let mut ids = Vec::with_capacity(points.len());
        for p in points {
            let key = [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()];
            let i = *index.entry(key).or_insert_with(|| {
                vertices.push(*p);
                vertices.len() - 1
            });
            ids.push(i);
        }
        Surface {
            vertices,
            triangles: ids.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        }
    }

    fn point(&self, i: usize) -> V3 {
        V3::from(self.vertices[i])
    }

    /// Unit normal (right-handed winding) and area of each triangle.
    fn face_normals(&self) -> Vec<(V3, f64)> {
        self.triangles
            .iter()
            .map(|t| {
                let n = (self.point(t[1]) - self.point(t[0]))
                    .cross(&(self.point(t[2]) - self.point(t[0])));
                let a = n.norm();
                if a > 0.0 && a.is_finite() {
                    (n / a, 0.5 * a)
                } else {
                    (V3::zeros(), 0.0)
                }
            })
            .collect()
    }

    /// Normals at the three corners of every triangle: the area-weighted
    /// mean of the normals of the triangles around the corner's vertex that
    /// turn less than `crease` (rad) from this triangle's (so that a box
    /// keeps flat faces and a smooth surface looks smooth).
    fn corner_normals(&self, crease: f64) -> Vec<[V3; 3]> {
        let faces = self.face_normals();
        let mut around: Vec<Vec<usize>> = vec![Vec::new(); self.vertices.len()];
        for (k, t) in self.triangles.iter().enumerate() {
            for &i in t {
                around[i].push(k);
            }
        }
        let cos = crease.cos();
        self.triangles
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let nk = faces[k].0;
                let mut c = [nk; 3];
                for (j, &i) in t.iter().enumerate() {
                    let mut s = V3::zeros();
                    for &f in &around[i] {
                        if faces[f].0.dot(&nk) >= cos {
                            s += faces[f].0 * faces[f].1;
                        }
                    }
                    if s.norm() > 0.0 {
                        c[j] = s.normalize();
                    }
                }
                c
            })
            .collect()
    }
}

/// How a camera maps view coordinates to pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Pinhole camera: focal length in pixels.
    Perspective { focal_px: f64 },
    /// Parallel projection: pixels per metre.
    Orthographic { px_per_m: f64 },
}

/// A camera: an eye, an orthonormal basis (right, up, forward: the viewing
/// direction) and a projection onto a view of `size` pixels whose optical
/// axis falls on pixel `centre_px`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub eye: [f64; 3],
    pub right: [f64; 3],
    pub up: [f64; 3],
    pub forward: [f64; 3],
    pub projection: Projection,
    pub centre_px: [f64; 2],
}

impl Camera {
    /// A camera at `eye` looking along `forward`, with world z (or y when
    /// looking straight up or down) as the up direction; projection and
    /// centre still to be set.
    fn looking(eye: V3, forward: V3) -> Camera {
        let f = forward.normalize();
        let hint = if f.z.abs() > 0.999 { V3::y() } else { V3::z() };
        let r = f.cross(&hint).normalize();
        let u = r.cross(&f);
        Camera {
            eye: eye.into(),
            right: r.into(),
            up: u.into(),
            forward: f.into(),
            projection: Projection::Orthographic { px_per_m: 1.0 },
            centre_px: [0.0, 0.0],
        }
    }

    /// View coordinates of a point: along right, up and forward from the eye.
    fn view(&self, p: &V3) -> V3 {
        let d = p - V3::from(self.eye);
        V3::new(
            d.dot(&V3::from(self.right)),
            d.dot(&V3::from(self.up)),
            d.dot(&V3::from(self.forward)),
        )
    }

    /// Pixel coordinates (x right, y down, pixel centres at half integers)
    /// and a depth key that grows towards the viewer and is linear across
    /// the screen (1/distance for a perspective, −distance for a parallel
    /// projection). `None` for a point behind a perspective camera.
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 3]> {
        let v = self.view(&V3::from(p));
        match self.projection {
            Projection::Perspective { focal_px } => {
                if v.z <= 1e-6 {
                    return None;
                }
                Some([
                    self.centre_px[0] + focal_px * v.x / v.z,
                    self.centre_px[1] - focal_px * v.y / v.z,
                    1.0 / v.z,
                ])
            }
            Projection::Orthographic { px_per_m } => Some([
                self.centre_px[0] + px_per_m * v.x,
                self.centre_px[1] - px_per_m * v.y,
                -v.z,
            ]),
        }
    }

    /// Distance along the viewing direction of a depth key from [`Camera::project`].
    fn distance(&self, q: f64) -> f64 {
        match self.projection {
            Projection::Perspective { .. } => 1.0 / q,
            Projection::Orthographic { .. } => -q,
        }
    }

    /// Unit vector from a point towards the viewer.
    fn towards_viewer(&self, p: &V3) -> V3 {
        match self.projection {
            Projection::Perspective { .. } => (V3::from(self.eye) - p).normalize(),
            Projection::Orthographic { .. } => -V3::from(self.forward),
        }
    }

    /// Sets the projection's scale and centre so that `points` fill the
    /// rectangle `(x0, y0)–(x1, y1)` of the view (centred, aspect kept).
    fn frame(&mut self, points: &[V3], x0: f64, y0: f64, x1: f64, y1: f64) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let persp = matches!(self.projection, Projection::Perspective { .. });
        for p in points {
            let v = self.view(p);
            let (a, b) = if persp {
                if v.z <= 1e-6 {
                    continue;
                }
                (v.x / v.z, v.y / v.z)
            } else {
                (v.x, v.y)
            };
            lo = [lo[0].min(a), lo[1].min(b)];
            hi = [hi[0].max(a), hi[1].max(b)];
        }
        if !lo[0].is_finite() {
            lo = [-1.0, -1.0];
            hi = [1.0, 1.0];
        }
        let ext = [(hi[0] - lo[0]).max(1e-9), (hi[1] - lo[1]).max(1e-9)];
        let mut s = ((x1 - x0) / ext[0]).min((y1 - y0) / ext[1]);
        if !s.is_finite() || s <= 0.0 {
            s = 1.0;
        }
        let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        self.centre_px = [(x0 + x1) / 2.0 - s * mid[0], (y0 + y1) / 2.0 + s * mid[1]];
        self.projection = if persp {
            Projection::Perspective { focal_px: s }
        } else {
            Projection::Orthographic { px_per_m: s }
        };
    }
}

/// A rectangle of the picture, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    pub x: usize,
    pub y: usize,
    pub w: usize,
    pub h: usize,
}

/// One view of a picture: where it is, what camera draws it. The camera's
/// pixel coordinates are relative to the rectangle's top-left corner.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    pub rect: Rect,
    pub camera: Camera,
    pub label: String,
}

/// The three views of a picture, and the corners kept for overlays.
#[derive(Debug, Clone, PartialEq)]
pub struct Views {
    /// Perspective from the front left, 30° above the horizontal.
    pub main: View,
    /// Orthographic, looking down −z: x to the right, y up.
    pub top: View,
    /// Orthographic, looking along +y: x to the right, z up.
    pub front: View,
    /// Where the strain legend goes (top right of the top view, outside the
    /// part the top view is framed in).
    pub legend: Rect,
    /// Where the world axes of the perspective view are drawn (bottom left).
    pub triad: Rect,
}

/// The cloth colour (upper side).
pub const CLOTH: Rgb = [70, 135, 210];
/// The cloth colour (underside).
pub const CLOTH_BACK: Rgb = [110, 160, 220];
/// The obstacle colour.
pub const OBSTACLE: Rgb = [170, 170, 166];
/// The strain colour map (stops of viridis), from zero strain to the
/// legend's full scale.
const STRAIN_MAP: [Rgb; 5] = [
    [68, 1, 84],
    [59, 82, 139],
    [33, 145, 140],
    [94, 201, 98],
    [253, 231, 37],
];
/// Height of the title bar, pixels.
const TITLE_H: usize = 44;
/// Supersampling factor per axis.
const SS: usize = 2;
/// Width of the strain legend, pixels.
const LEGEND_W: usize = 76;

/// A picture of a cloth and its obstacles.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Big text at the top left (the scene's name).
    pub title: String,
    /// Smaller text after the title (fabric, grid, time).
    pub info: Vec<String>,
    pub cloth: Surface,
    /// Per-vertex strain of the cloth (l/l0 − 1); colours the top view.
    pub strain: Option<Vec<f64>>,
    pub obstacles: Vec<Surface>,
    /// Width and height, pixels (at least 300 × 200 are drawn).
    pub size: (usize, usize),
}

impl Picture {
    pub fn new(title: &str, cloth: Surface) -> Picture {
        Picture {
            title: title.to_string(),
            info: Vec::new(),
            cloth,
            strain: None,
            obstacles: Vec::new(),
            size: (1200, 800),
        }
    }

    /// The state of a simulation: cloth, strains, obstacles where they are,
    /// with the fabric, the grid and the time as labels.
    pub fn from_simulation(sim: &crate::solver::Simulation, title: &str) -> Picture {
        let c = &sim.cloth;
        let mut p = Picture::new(
            title,
            Surface {
                vertices: c.positions().iter().map(|p| [p.x, p.y, p.z]).collect(),
                triangles: c.triangles.clone(),
            },
        );
        p.strain = Some(vertex_strain(sim));
        p.obstacles = sim.obstacles().iter().map(Surface::from_obstacle).collect();
        p.info = vec![
            format!("fabric {}", sim.fabric.name),
            format!(
                "grid {} x {} ({:.1} x {:.1} cm)",
                c.nx,
                c.ny,
                100.0 * c.lc,
                100.0 * c.lt
            ),
            format!("t = {:.2} s", sim.time),
        ];
        p
    }

    /// The points the views are framed on: the cloth and the obstacles, or
    /// only the part of the obstacles' bounding box near the cloth when the
    /// obstacles are far larger than it (a floor).
    fn framing_points(&self) -> Vec<V3> {
        let mut pts: Vec<V3> = self.cloth.vertices.iter().map(|&p| V3::from(p)).collect();
        let (clo, chi) = bounds(&pts);
        let obs: Vec<V3> = self
            .obstacles
            .iter()
            .flat_map(|s| s.vertices.iter().map(|&p| V3::from(p)))
            .collect();
        if pts.is_empty() {
            return obs;
        }
        let (olo, ohi) = bounds(&obs);
        let csize = (chi - clo).norm().max(1e-3);
        if !obs.is_empty() && (ohi - olo).norm() > 3.0 * csize {
            let m = V3::repeat(0.25 * csize);
            let (lo, hi) = (clo - m, chi + m);
            let (lo, hi) = (lo.sup(&olo), hi.inf(&ohi));
            if lo.iter().zip(hi.iter()).all(|(a, b)| a <= b) {
                pts.extend(box_corners(&lo, &hi));
            }
        } else {
            pts.extend(obs);
        }
        pts
    }

    /// Width and height drawn.
    fn dims(&self) -> (usize, usize) {
        (self.size.0.max(300), self.size.1.max(200))
    }

    /// Where the views are and how they are framed.
    pub fn views(&self) -> Views {
        let (w, h) = self.dims();
        let side = w / 3;
        let main_rect = Rect {
            x: 0,
            y: TITLE_H,
            w: w - side,
            h: h - TITLE_H,
        };
        let half = (h - TITLE_H) / 2;
        let top_rect = Rect {
            x: w - side,
            y: TITLE_H,
            w: side,
            h: half,
        };
        let front_rect = Rect {
            x: w - side,
            y: TITLE_H + half,
            w: side,
            h: h - TITLE_H - half,
        };
        let pts = self.framing_points();
        let (lo, hi) = bounds(&pts);
        let centre = (lo + hi) / 2.0;
        let radius = ((hi - lo).norm() / 2.0).max(1e-3);
        // margins: room for the label at the top, the scale bar below and
        // (top view) the legend at the right
        let fit = |cam: &mut Camera, r: &Rect, right_margin: f64| {
            cam.frame(
                &pts,
                24.0,
                28.0,
                r.w as f64 - right_margin,
                r.h as f64 - 50.0,
            )
        };
        let (el, az) = (30f64.to_radians(), 35f64.to_radians());
        // from the front (−y) and the left (−x), looking down at 30°
        let to_eye = V3::new(-az.sin() * el.cos(), -az.cos() * el.cos(), el.sin());
        let mut main = Camera::looking(centre + 4.0 * radius * to_eye, -to_eye);
        main.projection = Projection::Perspective { focal_px: 1.0 };
        main.frame(
            &pts,
            40.0,
            40.0,
            main_rect.w as f64 - 40.0,
            main_rect.h as f64 - 40.0,
        );
        let mut top = Camera::looking(centre + V3::z() * 2.0 * radius, -V3::z());
        fit(&mut top, &top_rect, LEGEND_W as f64 + 8.0);
        let mut front = Camera::looking(centre - V3::y() * 2.0 * radius, V3::y());
        fit(&mut front, &front_rect, 24.0);
        Views {
            main: View {
                rect: main_rect,
                camera: main,
                label: "perspective, from the front left".into(),
            },
            top: View {
                rect: top_rect,
                camera: top,
                label: "top (x right, y up)".into(),
            },
            front: View {
                rect: front_rect,
                camera: front,
                label: "front (x right, z up)".into(),
            },
            legend: Rect {
                x: top_rect.x + top_rect.w - LEGEND_W,
                y: top_rect.y + 20,
                w: LEGEND_W,
                h: 150,
            },
            triad: Rect {
                x: main_rect.x,
                y: main_rect.y + main_rect.h - 80,
                w: 80,
                h: 80,
            },
        }
    }

    /// Strain at the top of the legend: the largest strain rounded up to 1,
    /// 2 or 5 × 10^k, at least 0.1 %.
    fn strain_full_scale(&self) -> Option<f64> {
        let s = self.strain.as_ref()?;
        let m = s
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        let m = m.max(0.001);
        let mag = 10f64.powf(m.log10().floor());
        [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|k| k * mag)
            .find(|v| *v >= m * (1.0 - 1e-12))
    }

    /// Draws the picture.
    pub fn render(&self) -> Image {
        let (w, h) = self.dims();
        let mut img = Image::new(w, h, plot::WHITE);
        let views = self.views();
        let full = self.strain_full_scale();
        let cloth_colours = |front: bool| -> Vec<Rgb> {
            vec![if front { CLOTH } else { CLOTH_BACK }; self.cloth.vertices.len()]
        };
        let strain_colours: Option<Vec<Rgb>> = match (&self.strain, full) {
            (Some(s), Some(f)) if s.len() == self.cloth.vertices.len() => {
                Some(s.iter().map(|&e| colour_map(e / f)).collect())
            }
            _ => None,
        };
        for (view, strained) in [
            (&views.main, false),
            (&views.top, strain_colours.is_some()),
            (&views.front, false),
        ] {
            let mut r = Raster::new(view.rect.w * SS, view.rect.h * SS);
            let mut cam = view.camera;
            cam.centre_px = [cam.centre_px[0] * SS as f64, cam.centre_px[1] * SS as f64];
            cam.projection = match cam.projection {
                Projection::Perspective { focal_px } => Projection::Perspective {
                    focal_px: focal_px * SS as f64,
                },
                Projection::Orthographic { px_per_m } => Projection::Orthographic {
                    px_per_m: px_per_m * SS as f64,
                },
            };
            for (k, o) in self.obstacles.iter().enumerate() {
                let c = vec![OBSTACLE; o.vertices.len()];
                r.draw(&cam, o, &c, &c, 0.6, 2 + k as u16);
            }
            let (fc, bc) = if strained {
                let s = strain_colours.clone().expect("strain colours");
                (s.clone(), s)
            } else {
                (cloth_colours(true), cloth_colours(false))
            };
            r.draw(&cam, &self.cloth, &fc, &bc, 1.2, 1);
            r.outline(&cam, 0.01 * scene_size(&self.framing_points()));
            let sub = r.resolve(SS);
            blit(&mut img, &sub, view.rect.x as i64, view.rect.y as i64);
        }
        self.decorate(
            &mut img,
            &views,
            if strain_colours.is_some() { full } else { None },
        );
        img
    }

    /// Labels, frames, scale bars, axes and the strain legend.
    fn decorate(&self, img: &mut Image, views: &Views, strain_full: Option<f64>) {
        let w = img.width;
        // title bar
        img.text(14, 14, &self.title, 2, plot::BLACK);
        let info = self.info.join("   ");
        let x = 14 + plot::text_width(&self.title, 2) + 24;
        img.text(x, 18, &info, 1, [60, 60, 60]);
        let line = (TITLE_H - 1) as f64;
        img.line((0.0, line), (w as f64, line), plot::GREY, 1);
        for v in [&views.main, &views.top, &views.front] {
            let r = v.rect;
            img.text(r.x as i64 + 10, r.y as i64 + 10, &v.label, 1, [60, 60, 60]);
        }
        let (tx, ty) = (views.top.rect.x as f64, views.top.rect.y as f64);
        img.line(
            (tx, ty),
            (tx, (views.front.rect.y + views.front.rect.h) as f64),
            plot::GREY,
            1,
        );
        let fy = views.front.rect.y as f64;
        img.line((tx, fy), (w as f64, fy), plot::GREY, 1);
        for v in [&views.top, &views.front] {
            if let Projection::Orthographic { px_per_m } = v.camera.projection {
                scale_bar(img, &v.rect, px_per_m);
            }
            let names = if v.camera.forward[2] < -0.5 {
                ("x", "y")
            } else {
                ("x", "z")
            };
            axes_2d(img, &v.rect, names);
        }
        triad(img, &views.main.camera, &views.triad);
        if let Some(f) = strain_full {
            legend(img, &views.legend, f);
        }
    }

    pub fn save_png(&self, path: &Path) -> Result<()> {
        self.render().save_png(path)
    }
}

/// A cloth coloured by a per-vertex field (a garment's strain or pressure
/// map) on its obstacles (the body), seen orthographically from the front
/// (looking along +y), the back and the left side (looking along +x), with
/// a colour bar from 0 to `full` labelled in `unit` × `label_scale`.
#[derive(Debug, Clone)]
pub struct FieldPicture {
    pub title: String,
    pub info: Vec<String>,
    pub cloth: Surface,
    pub field: Vec<f64>,
    /// The field's value at the top of the colour bar.
    pub full: f64,
    /// Name and unit of the colour bar, e.g. ("stretch", "%"), and the
    /// factor from the field to the unit.
    pub label: (String, String),
    pub label_scale: f64,
    pub obstacles: Vec<Surface>,
    pub size: (usize, usize),
}

impl FieldPicture {
    /// Draws the picture.
    pub fn render(&self) -> Image {
        let (w, h) = (self.size.0.max(600), self.size.1.max(300));
        let mut img = Image::new(w, h, plot::WHITE);
        let legend_w = 110;
        let vw = (w - legend_w) / 3;
        let vh = h - TITLE_H;
        let mut pts: Vec<V3> = self.cloth.vertices.iter().map(|&p| V3::from(p)).collect();
        for o in &self.obstacles {
            pts.extend(o.vertices.iter().map(|&p| V3::from(p)));
        }
        let (lo, hi) = bounds(&pts);
        let centre = (lo + hi) / 2.0;
        let radius = ((hi - lo).norm() / 2.0).max(1e-3);
        let colours: Vec<Rgb> = self
            .field
            .iter()
            .map(|&f| colour_map(if self.full > 0.0 { f / self.full } else { 0.0 }))
            .collect();
        let views = [
            ("front", V3::y()),
            ("back", -V3::y()),
            ("left side", V3::x()),
        ];
        // one scale for the three views: the largest that fits all
        let mut cams: Vec<Camera> = views
            .iter()
            .map(|(_, f)| {
                let mut c = Camera::looking(centre - f * 2.0 * radius, *f);
                c.frame(&pts, 20.0, 30.0, vw as f64 - 20.0, vh as f64 - 40.0);
                c
            })
            .collect();
        let s = cams
            .iter()
            .map(|c| match c.projection {
                Projection::Orthographic { px_per_m } => px_per_m,
                Projection::Perspective { focal_px } => focal_px,
            })
            .fold(f64::INFINITY, f64::min);
        for (k, cam) in cams.iter_mut().enumerate() {
            cam.projection = Projection::Orthographic { px_per_m: s };
            let c = cam.view(&centre);
            cam.centre_px = [
                vw as f64 / 2.0 - s * c.x,
                (vh as f64 + 10.0) / 2.0 + s * c.y,
            ];
            let mut r = Raster::new(vw * SS, vh * SS);
            let mut sc = *cam;
            sc.centre_px = [sc.centre_px[0] * SS as f64, sc.centre_px[1] * SS as f64];
            sc.projection = Projection::Orthographic {
                px_per_m: s * SS as f64,
            };
            for (q, o) in self.obstacles.iter().enumerate() {
                let oc = vec![OBSTACLE; o.vertices.len()];
                r.draw(&sc, o, &oc, &oc, 0.6, 2 + q as u16);
            }
            r.draw(&sc, &self.cloth, &colours, &colours, 1.2, 1);
            r.outline(&sc, 0.01 * scene_size(&pts));
            let sub = r.resolve(SS);
            let x0 = (k * vw) as i64;
            blit(&mut img, &sub, x0, TITLE_H as i64);
            img.text(x0 + 10, TITLE_H as i64 + 8, views[k].0, 1, [60, 60, 60]);
            if k > 0 {
                img.line(
                    (x0 as f64, TITLE_H as f64),
                    (x0 as f64, h as f64),
                    plot::GREY,
                    1,
                );
            }
            let rect = Rect {
                x: k * vw,
                y: TITLE_H,
                w: vw,
                h: vh,
            };
            scale_bar(&mut img, &rect, s);
        }
        img.text(14, 14, &self.title, 2, plot::BLACK);
        let x = 14 + plot::text_width(&self.title, 2) + 24;
        img.text(x, 18, &self.info.join("   "), 1, [60, 60, 60]);
        img.line(
            (0.0, (TITLE_H - 1) as f64),
            (w as f64, (TITLE_H - 1) as f64),
            plot::GREY,
            1,
        );
        // colour bar
        let (bx, y0, bh) = ((3 * vw) as i64 + 20, TITLE_H as i64 + 50, 200i64);
        for k in 0..bh {
            let c = colour_map(1.0 - k as f64 / (bh - 1) as f64);
            img.fill_rect(bx, y0 + k, 14, 1, c);
        }
        let val = |v: f64| {
            let s = format!("{:.2}", v * self.label_scale);
            format!(
                "{} {}",
                s.trim_end_matches('0').trim_end_matches('.'),
                self.label.1
            )
        };
        img.text(bx + 18, y0 - 3, &val(self.full), 1, plot::BLACK);
        img.text(
            bx + 18,
            y0 + bh / 2 - 4,
            &val(self.full / 2.0),
            1,
            plot::BLACK,
        );
        img.text(bx + 18, y0 + bh - 6, &val(0.0), 1, plot::BLACK);
        // the name above the bar, in lines that fit the legend's width
        let mut lines: Vec<String> = Vec::new();
        for word in self.label.0.split_whitespace() {
            match lines.last_mut() {
                Some(l) if plot::text_width(&format!("{l} {word}"), 1) <= legend_w as i64 - 12 => {
                    l.push(' ');
                    l.push_str(word);
                }
                _ => lines.push(word.to_string()),
            }
        }
        for (k, l) in lines.iter().rev().enumerate() {
            img.text(bx - 6, y0 - 20 - 12 * k as i64, l, 1, plot::BLACK);
        }
        img
    }

    pub fn save_png(&self, path: &Path) -> Result<()> {
        self.render().save_png(path)
    }
}

/// A round full scale (1, 2 or 5 × 10^k) at or above the largest finite
/// value of `v`, at least `floor`.
pub fn full_scale(v: &[f64], floor: f64) -> f64 {
    let m = v
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max)
        .max(floor);
    let mag = 10f64.powf(m.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|k| k * mag)
        .find(|x| *x >= m * (1.0 - 1e-12))
        .unwrap_or(m)
}

fn bounds(pts: &[V3]) -> (V3, V3) {
    let mut lo = V3::repeat(f64::INFINITY);
    let mut hi = V3::repeat(f64::NEG_INFINITY);
    for p in pts.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    if !lo.x.is_finite() {
        return (V3::zeros(), V3::zeros());
    }
    (lo, hi)
}

fn box_corners(lo: &V3, hi: &V3) -> Vec<V3> {
    (0..8)
        .map(|k| {
            V3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect()
}

fn scene_size(pts: &[V3]) -> f64 {
    let (lo, hi) = bounds(pts);
    (hi - lo).norm().max(1e-3)
}

/// The colour of `t` ∈ [0, 1] on the strain map (clamped).
pub fn colour_map(t: f64) -> Rgb {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (STRAIN_MAP.len() - 1) as f64;
    let k = (x.floor() as usize).min(STRAIN_MAP.len() - 2);
    let f = x - k as f64;
    let (a, b) = (STRAIN_MAP[k], STRAIN_MAP[k + 1]);
    [0, 1, 2].map(|c| (a[c] as f64 + f * (b[c] as f64 - a[c] as f64)).round() as u8)
}

/// Copies `src` into `dst` with its top-left corner at (x, y).
fn blit(dst: &mut Image, src: &Image, x: i64, y: i64) {
    for j in 0..src.height {
        for i in 0..src.width {
            dst.set(x + i as i64, y + j as i64, src.get(i, j));
        }
    }
}

/// A "nice" length (1, 2 or 5 × 10^k m) close to `target` m, not above it.
fn nice_length(target: f64) -> f64 {
    let mag = 10f64.powf(target.log10().floor());
    [5.0, 2.0, 1.0]
        .iter()
        .map(|k| k * mag)
        .find(|v| *v <= target)
        .unwrap_or(mag)
}

fn length_label(m: f64) -> String {
    let cm = 100.0 * m;
    if cm >= 1.0 {
        format!("{} cm", cm.round())
    } else {
        format!("{} mm", (10.0 * cm).round())
    }
}

/// A scale bar at the bottom left of an orthographic view.
fn scale_bar(img: &mut Image, r: &Rect, px_per_m: f64) {
    let len = nice_length(0.3 * r.w as f64 / px_per_m);
    let px = len * px_per_m;
    let (x0, y) = (r.x as f64 + 16.0, (r.y + r.h) as f64 - 18.0);
    let c = plot::BLACK;
    img.line((x0, y), (x0 + px, y), c, 2);
    img.line((x0, y - 5.0), (x0, y + 4.0), c, 2);
    img.line((x0 + px, y - 5.0), (x0 + px, y + 4.0), c, 2);
    let s = length_label(len);
    img.text(
        (x0 + px / 2.0) as i64 - plot::text_width(&s, 1) / 2,
        y as i64 - 15,
        &s,
        1,
        c,
    );
}

/// Small axis arrows at the bottom right of an orthographic view.
fn axes_2d(img: &mut Image, r: &Rect, names: (&str, &str)) {
    let (ox, oy) = ((r.x + r.w) as f64 - 44.0, (r.y + r.h) as f64 - 10.0);
    let (c, l) = ([90, 90, 90], 20.0);
    img.line((ox, oy), (ox + l, oy), c, 1);
    img.line((ox + l, oy), (ox + l - 4.0, oy - 3.0), c, 1);
    img.line((ox + l, oy), (ox + l - 4.0, oy + 3.0), c, 1);
    img.line((ox, oy), (ox, oy - l), c, 1);
    img.line((ox, oy - l), (ox - 3.0, oy - l + 4.0), c, 1);
    img.line((ox, oy - l), (ox + 3.0, oy - l + 4.0), c, 1);
    img.text((ox + l) as i64 + 4, oy as i64 - 4, names.0, 1, c);
    img.text(ox as i64 + 6, (oy - l) as i64 - 4, names.1, 1, c);
}

/// The world axes as seen by a camera, centred in `r`.
fn triad(img: &mut Image, cam: &Camera, r: &Rect) {
    let (ox, oy) = ((r.x + r.w / 2) as f64, (r.y + r.h / 2) as f64);
    for (axis, name, c) in [
        (V3::x(), "x", [200, 40, 40]),
        (V3::y(), "y", [30, 150, 60]),
        (V3::z(), "z", [40, 70, 200]),
    ] {
        let (dx, dy) = (axis.dot(&V3::from(cam.right)), -axis.dot(&V3::from(cam.up)));
        let e = (ox + 24.0 * dx, oy + 24.0 * dy);
        img.line((ox, oy), e, c, 2);
        img.text(
            (ox + 32.0 * dx) as i64 - 4,
            (oy + 32.0 * dy) as i64 - 4,
            name,
            1,
            c,
        );
    }
}

/// The strain colour bar, in `r`.
fn legend(img: &mut Image, r: &Rect, full: f64) {
    let (x, y0, h) = (r.x as i64 + 14, r.y as i64 + 20, 120i64);
    for k in 0..h {
        let c = colour_map(1.0 - k as f64 / (h - 1) as f64);
        img.fill_rect(x, y0 + k, 12, 1, c);
    }
    let g = plot::GREY;
    img.line((x as f64, y0 as f64), ((x + 11) as f64, y0 as f64), g, 1);
    // percent with up to three decimals, trailing zeros dropped
    let pct = |v: f64| {
        let s = format!("{:.3}", 100.0 * v);
        format!("{}%", s.trim_end_matches('0').trim_end_matches('.'))
    };
    img.text(x + 16, y0 - 3, &pct(full), 1, plot::BLACK);
    img.text(x + 16, y0 + h / 2 - 4, &pct(full / 2.0), 1, plot::BLACK);
    img.text(x + 16, y0 + h - 6, "0", 1, plot::BLACK);
    img.text(x - 10, y0 - 16, "strain", 1, plot::BLACK);
}

/// A render target: colour, depth key (larger is nearer) and object id
/// (0: background, 1: cloth, 2 + k: obstacle k) per pixel.
struct Raster {
    w: usize,
    h: usize,
    colour: Vec<[f32; 3]>,
    depth: Vec<f64>,
    id: Vec<u16>,
}

/// Ambient light, key light and fill light strengths.
const AMBIENT: f64 = 0.25;
const KEY: f64 = 0.75;
const FILL: f64 = 0.25;

impl Raster {
    fn new(w: usize, h: usize) -> Raster {
        Raster {
            w,
            h,
            colour: vec![[255.0; 3]; w * h],
            depth: vec![f64::NEG_INFINITY; w * h],
            id: vec![0; w * h],
        }
    }

    /// Fills the triangle with corners `p` (pixel x, y and depth key),
    /// colours interpolated between the corners (Gouraud), where it is
    /// nearer than what is drawn. Pixels whose centre lies inside are filled;
    /// a centre on an edge belongs to the triangle on the edge's top or left
    /// side, so triangles sharing an edge fill each pixel once.
    fn triangle(&mut self, p: [[f64; 3]; 3], c: [[f32; 3]; 3], id: u16) {
        let area =
            (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
        if area == 0.0 || !area.is_finite() {
            return;
        }
        // orient counter-clockwise on screen (y down: positive area)
        let (p, c) = if area < 0.0 {
            ([p[0], p[2], p[1]], [c[0], c[2], c[1]])
        } else {
            (p, c)
        };
        let area = area.abs();
        let xmin = p.iter().map(|v| v[0]).fold(f64::INFINITY, f64::min);
        let xmax = p.iter().map(|v| v[0]).fold(f64::NEG_INFINITY, f64::max);
        let ymin = p.iter().map(|v| v[1]).fold(f64::INFINITY, f64::min);
        let ymax = p.iter().map(|v| v[1]).fold(f64::NEG_INFINITY, f64::max);
        let x0 = (xmin - 0.5).ceil().max(0.0) as usize;
        let y0 = (ymin - 0.5).ceil().max(0.0) as usize;
        let x1 = ((xmax - 0.5).floor() + 1.0).clamp(0.0, self.w as f64) as usize;
        let y1 = ((ymax - 0.5).floor() + 1.0).clamp(0.0, self.h as f64) as usize;
        // edge k runs from corner k+1 to corner k+2 (opposite corner k)
        let edge = |k: usize| {
            let (a, b) = (p[(k + 1) % 3], p[(k + 2) % 3]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            // with y down and counter-clockwise order: a top edge runs to
            // the right along a row, a left edge runs up the screen
            let top_left = (dy == 0.0 && dx > 0.0) || dy < 0.0;
            (a, dx, dy, top_left)
        };
        let edges = [edge(0), edge(1), edge(2)];
        for y in y0..y1 {
            let py = y as f64 + 0.5;
            for x in x0..x1 {
                let px = x as f64 + 0.5;
                let mut w = [0.0; 3];
                let mut inside = true;
                for (k, (a, dx, dy, tl)) in edges.iter().enumerate() {
                    // positive inside (the corner k side)
                    let e = dx * (py - a[1]) - dy * (px - a[0]);
                    if e < 0.0 || (e == 0.0 && !tl) {
                        inside = false;
                        break;
                    }
                    w[k] = e / area;
                }
                if !inside {
                    continue;
                }
                let q = w[0] * p[0][2] + w[1] * p[1][2] + w[2] * p[2][2];
                let i = y * self.w + x;
                if q > self.depth[i] {
                    self.depth[i] = q;
                    self.id[i] = id;
                    let (a, b) = (w[0] as f32, w[1] as f32);
                    let g = 1.0 - a - b;
                    self.colour[i] = [0, 1, 2].map(|ch| a * c[0][ch] + b * c[1][ch] + g * c[2][ch]);
                }
            }
        }
    }

    /// Draws a surface lit from the camera's upper right (a fill light from
    /// the left): `front` colours
    /// where the viewer sees the side its triangles' winding points to,
    /// `back` colours elsewhere (both lit on the side seen).
    fn draw(
        &mut self,
        cam: &Camera,
        s: &Surface,
        front: &[Rgb],
        back: &[Rgb],
        crease: f64,
        id: u16,
    ) {
        let normals = s.corner_normals(crease);
        let (r, u, f) = (V3::from(cam.right), V3::from(cam.up), V3::from(cam.forward));
        let key = (0.4 * r + 0.45 * u - 0.8 * f).normalize();
        let fill = (-0.8 * r + 0.1 * u - 0.4 * f).normalize();
        let proj: Vec<Option<[f64; 3]>> = s.vertices.iter().map(|&v| cam.project(v)).collect();
        for (t, ns) in s.triangles.iter().zip(&normals) {
            let (Some(a), Some(b), Some(c)) = (proj[t[0]], proj[t[1]], proj[t[2]]) else {
                continue;
            };
            let pa = s.point(t[0]);
            let nf = (s.point(t[1]) - pa).cross(&(s.point(t[2]) - pa));
            let centroid = (pa + s.point(t[1]) + s.point(t[2])) / 3.0;
            let seen_front = nf.dot(&cam.towards_viewer(&centroid)) >= 0.0;
            let sign = if seen_front { 1.0 } else { -1.0 };
            let colours = if seen_front { front } else { back };
            let lit = |k: usize| -> [f32; 3] {
                let n = ns[k] * sign;
                let i = AMBIENT + KEY * n.dot(&key).max(0.0) + FILL * n.dot(&fill).max(0.0);
                let base = colours[t[k]];
                base.map(|ch| (ch as f64 * i).min(255.0) as f32)
            };
            self.triangle([a, b, c], [lit(0), lit(1), lit(2)], id);
        }
    }

    /// Darkens the pixels where the object changes, or where the surface
    /// seen jumps by more than `jump` m in depth (a fold in front of cloth
    /// farther away).
    fn outline(&mut self, cam: &Camera, jump: f64) {
        let mut edge = vec![false; self.w * self.h];
        for y in 0..self.h {
            for x in 0..self.w {
                let i = y * self.w + x;
                for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                    if nx >= self.w || ny >= self.h {
                        continue;
                    }
                    let j = ny * self.w + nx;
                    let differs = if self.id[i] != self.id[j] {
                        true
                    } else if self.id[i] != 0 {
                        (cam.distance(self.depth[i]) - cam.distance(self.depth[j])).abs() > jump
                    } else {
                        false
                    };
                    if differs {
                        // mark the nearer pixel (the one in front)
                        if self.depth[i] >= self.depth[j] {
                            edge[i] = true;
                        } else {
                            edge[j] = true;
                        }
                    }
                }
            }
        }
        for (c, e) in self.colour.iter_mut().zip(&edge) {
            if *e {
                *c = c.map(|v| v * 0.35);
            }
        }
    }

    /// The image, each `ss` × `ss` block of pixels averaged into one.
    fn resolve(&self, ss: usize) -> Image {
        let (w, h) = (self.w / ss, self.h / ss);
        let mut img = Image::new(w, h, plot::WHITE);
        let n = (ss * ss) as f32;
        for y in 0..h {
            for x in 0..w {
                let mut s = [0.0f32; 3];
                for dy in 0..ss {
                    for dx in 0..ss {
                        let c = self.colour[(y * ss + dy) * self.w + x * ss + dx];
                        for k in 0..3 {
                            s[k] += c[k];
                        }
                    }
                }
                img.set(
                    x as i64,
                    y as i64,
                    s.map(|v| (v / n).round().clamp(0.0, 255.0) as u8),
                );
            }
        }
        img
    }
}

/// Per-vertex strain: the largest engineering strain (l/l0 − 1) of the
/// tension springs at the vertex (positive: stretched).
pub fn vertex_strain(sim: &crate::solver::Simulation) -> Vec<f64> {
    let x = sim.cloth.positions();
    let mut s = vec![f64::NEG_INFINITY; x.len()];
    for sp in &sim.cloth.tension {
        let e = (x[sp.a] - x[sp.b]).norm() / sp.l0 - 1.0;
        s[sp.a] = s[sp.a].max(e);
        s[sp.b] = s[sp.b].max(e);
    }
    s.iter_mut().for_each(|v| {
        if !v.is_finite() {
            *v = 0.0
        }
    });
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(r: &Raster) -> usize {
        r.id.iter().filter(|&&i| i != 0).count()
    }

    #[test]
    fn a_triangle_fills_its_area() {
        // triangles in both windings, on and off the pixel grid; area by
        // the shoelace formula
        let tris: [[[f64; 2]; 3]; 3] = [
            [[10.0, 10.0], [190.0, 10.0], [10.0, 150.0]],
            [[3.3, 7.9], [120.2, 180.6], [170.7, 20.1]],
            [[50.25, 5.5], [20.75, 190.25], [199.0, 99.5]],
        ];
        for p in tris {
            let area = 0.5
                * ((p[0][0] * p[1][1] - p[1][0] * p[0][1])
                    + (p[1][0] * p[2][1] - p[2][0] * p[1][1])
                    + (p[2][0] * p[0][1] - p[0][0] * p[2][1]))
                    .abs();
            for order in [[0, 1, 2], [0, 2, 1]] {
                let mut r = Raster::new(200, 200);
                let q = order.map(|k| [p[k][0], p[k][1], 0.0]);
                r.triangle(q, [[0.0; 3]; 3], 1);
                let n = filled(&r) as f64;
                let perimeter: f64 = (0..3)
                    .map(|k| {
                        let (a, b) = (p[k], p[(k + 1) % 3]);
                        ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
                    })
                    .sum();
                // the pixels cut by the edges make at most about half the
                // perimeter of error
                assert!(
                    (n - area).abs() < 0.5 * perimeter,
                    "{n} pixels for an area {area}"
                );
                assert!((n - area).abs() / area < 0.02, "{n} vs {area}");
            }
        }
    }

    #[test]
    fn triangles_sharing_an_edge_fill_each_pixel_once() {
        // a square split along its diagonal on integer corners: the pixel
        // centres on the diagonal go to exactly one triangle
        let mut r = Raster::new(64, 64);
        let (a, b, c, d) = (
            [4.0, 4.0, 0.0],
            [60.0, 4.0, 0.0],
            [60.0, 60.0, 0.0],
            [4.0, 60.0, 0.0],
        );
        let mut count = vec![0u8; 64 * 64];
        for (k, t) in [[a, b, c], [a, c, d]].iter().enumerate() {
            let mut s = Raster::new(64, 64);
            s.triangle(*t, [[0.0; 3]; 3], 1 + k as u16);
            for (i, id) in s.id.iter().enumerate() {
                count[i] += (*id != 0) as u8;
            }
            r.triangle(*t, [[0.0; 3]; 3], 1 + k as u16);
        }
        assert_eq!(count.iter().filter(|&&c| c > 1).count(), 0);
        assert_eq!(filled(&r), 56 * 56);
    }

    #[test]
    fn the_nearer_triangle_hides_the_farther_one() {
        // two overlapping triangles; the depth key grows towards the viewer
        let big = [[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]];
        let small = [[10.0, 10.0], [60.0, 10.0], [10.0, 60.0]];
        let red = [[255.0, 0.0, 0.0]; 3];
        let blue = [[0.0, 0.0, 255.0]; 3];
        for near_first in [true, false] {
            let mut r = Raster::new(100, 100);
            let far_t = big.map(|p| [p[0], p[1], 1.0]);
            let near_t = small.map(|p| [p[0], p[1], 2.0]);
            if near_first {
                r.triangle(near_t, red, 2);
                r.triangle(far_t, blue, 1);
            } else {
                r.triangle(far_t, blue, 1);
                r.triangle(near_t, red, 2);
            }
            let near = r.id.iter().filter(|&&i| i == 2).count() as f64;
            assert!((near - 1250.0).abs() < 60.0, "{near}");
            // a pixel inside both shows the nearer one's colour
            assert_eq!(r.colour[30 * 100 + 20], [255.0, 0.0, 0.0]);
            assert_eq!(r.colour[80 * 100 + 5], [0.0, 0.0, 255.0]);
        }
        // a triangle crossing another: each shows where it is nearer
        let mut r = Raster::new(100, 100);
        r.triangle(
            [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]],
            red,
            1,
        );
        // depth from −1 at x = 0 to +1 at x = 100
        r.triangle(
            [[0.0, 0.0, -1.0], [100.0, 0.0, 1.0], [0.0, 100.0, -1.0]],
            blue,
            2,
        );
        assert_eq!(r.id[10 * 100 + 20], 1);
        assert_eq!(r.id[10 * 100 + 70], 2);
    }

    #[test]
    fn gouraud_colours_interpolate_between_corners() {
        let mut r = Raster::new(100, 100);
        r.triangle(
            [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]],
            [[0.0; 3], [200.0; 3], [0.0; 3]],
            1,
        );
        // at pixel centre x = 50.5 the weight of corner 1 is 0.505
        let c = r.colour[10 * 100 + 50][0];
        assert!((c - 101.0).abs() < 1e-3, "{c}");
    }

    #[test]
    fn orthographic_top_view_maps_x_right_and_y_up() {
        let cloth = Surface {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [0.4, 0.0, 0.0],
                [0.4, 0.2, 0.0],
                [0.0, 0.2, 0.0],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let p = Picture::new("t", cloth);
        let v = p.views();
        let cam = v.top.camera;
        let a = cam.project([0.0, 0.0, 0.0]).unwrap();
        let b = cam.project([0.4, 0.2, 0.0]).unwrap();
        assert!(b[0] > a[0] && b[1] < a[1]);
        let Projection::Orthographic { px_per_m } = cam.projection else {
            panic!("top view is orthographic")
        };
        assert!((b[0] - a[0] - 0.4 * px_per_m).abs() < 1e-9);
        // the 2:1 cloth fills the view's width less the margins and the legend
        assert!(((b[0] - a[0]) - (v.top.rect.w - 32 - LEGEND_W) as f64).abs() < 1e-6);
        // the front view sees the flat cloth as a line; a point above it is higher up
        let f = v.front.camera;
        assert!(f.project([0.2, 0.1, 0.1]).unwrap()[1] < f.project([0.2, 0.1, 0.0]).unwrap()[1]);
        // the perspective camera looks down from the front left
        let m = v.main.camera;
        assert!(m.eye[0] < 0.2 && m.eye[1] < 0.1 && m.eye[2] > 0.0);
        let down = -m.forward[2];
        assert!((down - 30f64.to_radians().sin()).abs() < 1e-9);
    }

    #[test]
    fn a_box_keeps_flat_faces_and_a_sheet_smooth_normals() {
        let o = Obstacle::new(
            "b",
            crate::collision::ShapeSpec::Box {
                size: [1.0, 1.0, 1.0],
            },
            nalgebra::Isometry3::identity(),
            0.0,
            0.0,
        )
        .unwrap();
        let s = Surface::from_obstacle(&o);
        let faces = s.face_normals();
        for (n, f) in s.corner_normals(0.6).iter().zip(&faces) {
            for c in n {
                assert!((c - f.0).norm() < 1e-12);
            }
        }
        // a folded sheet: across a 30° fold the corner normals are averaged
        let sheet = Surface {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [-1.0, 0.0, 30f64.to_radians().tan()],
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let n = sheet.corner_normals(1.2);
        assert!((n[0][0] - n[1][0]).norm() < 1e-12);
        assert!(n[0][0].z < 1.0 && n[0][0].x > 0.0);
    }

    #[test]
    fn the_strain_scale_is_a_round_number_above_the_largest_strain() {
        let mut p = Picture::new("t", Surface::default());
        for (max, full) in [(0.0, 0.001), (0.0042, 0.005), (0.01, 0.01), (0.0101, 0.02)] {
            p.strain = Some(vec![-0.01, max / 2.0, max]);
            assert!((p.strain_full_scale().unwrap() - full).abs() < 1e-15);
        }
    }

    #[test]
    fn a_floor_far_larger_than_the_cloth_does_not_shrink_it() {
        let cloth = Surface {
            vertices: vec![[0.0, 0.0, 0.1], [0.5, 0.0, 0.1], [0.0, 0.5, 0.1]],
            triangles: vec![[0, 1, 2]],
        };
        let floor = Obstacle::new(
            "floor",
            crate::collision::ShapeSpec::Box {
                size: [10.0, 10.0, 0.1],
            },
            nalgebra::Isometry3::translation(0.0, 0.0, -0.05),
            0.0,
            0.0,
        )
        .unwrap();
        let mut p = Picture::new("t", cloth);
        p.obstacles = vec![Surface::from_obstacle(&floor)];
        let v = p.views();
        let Projection::Orthographic { px_per_m } = v.top.camera.projection else {
            panic!("top view is orthographic")
        };
        // framed on the cloth grown on each side by a quarter of its
        // bounding box's diagonal (the flat cloth: 0.5 √2 m)
        let size = 0.5 * 2f64.sqrt();
        let framed = 0.5 + 2.0 * 0.25 * size;
        let width = (v.top.rect.w - 32 - LEGEND_W) as f64;
        assert!((px_per_m - width / framed).abs() < 1e-9, "{px_per_m}");
        // the floor is drawn beside the cloth
        let img = p.render();
        let c = v.top.camera.project([0.4, 0.4, 0.0]).unwrap();
        let px = img.get(v.top.rect.x + c[0] as usize, v.top.rect.y + c[1] as usize);
        assert!(px[0] == px[1] && px[0] < 250, "{px:?}");
    }

    #[test]
    fn triangle_lists_merge_equal_points() {
        let s = Surface::from_triangle_list(&[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ]);
        assert_eq!(s.vertices.len(), 4);
        assert_eq!(s.triangles, vec![[0, 1, 2], [1, 3, 2]]);
    }
}
