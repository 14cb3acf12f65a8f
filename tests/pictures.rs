//! Pictures of a drape: `drape` writes `final.png` and `bag export --format
//! png` draws a frame of a bag. The PNGs are decoded with the `png` crate and
//! checked against the shapes written as PLY: where the cloth's pixels are
//! must match the cloth's coordinates projected by the views' cameras
//! (the arithmetic of the projections is done here, from the cameras'
//! published parameters), and the obstacles must be grey where they are.

mod support;
use garment_sim::pictures::render::{Picture, Projection, Rect, Surface, View, Views};
use std::path::Path;

/// A 40 cm square of cloth falling onto a ball, and a block beside it.
const SCENE: &str = "name: ball_and_block
cloth:
  fabric: FABRIC
  size: [0.4, 0.4]
  spacing: 0.02
  pose: { position: [-0.2, -0.2, 0.3] }
obstacles:
  - id: ball
    shape: { type: sphere, radius: 0.1 }
    pose: { position: [0.0, 0.0, 0.1] }
  - id: block
    shape: { type: box, size: [0.1, 0.1, 0.1] }
    pose: { position: [0.45, 0.3, 0.05] }
dt: 0.008333333333333333
duration: 0.6
";

/// Top face centre and front face centre of the block.
const BLOCK_TOP: [f64; 3] = [0.45, 0.3, 0.1];
const BLOCK_FRONT: [f64; 3] = [0.45, 0.25, 0.05];

fn write_scene(dir: &Path) -> std::path::PathBuf {
    let fabric = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fabrics/acrylic.yaml");
    let p = dir.join("scene.yaml");
    std::fs::write(&p, SCENE.replace("FABRIC", &fabric.display().to_string())).unwrap();
    p
}

fn run(args: &[&str], extra: &[&Path]) -> String {
    support::stdout_of(support::garment_sim().args(args).args(extra))
}

/// Width, height and RGB pixels (row-major, top row first) of a PNG.
fn decode(path: &Path) -> (usize, usize, Vec<[u8; 3]>) {
    let f = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut r = png::Decoder::new(f).read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let px = buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width as usize, info.height as usize, px)
}

/// Vertex positions of an ASCII PLY file (the first three properties).
fn read_ply(path: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let mut n = 0;
    for l in lines.by_ref() {
        if let Some(v) = l.strip_prefix("element vertex ") {
            n = v.trim().parse().unwrap();
        }
        if l == "end_header" {
            break;
        }
    }
    let v: Vec<[f64; 3]> = lines
        .take(n)
        .map(|l| {
            let c: Vec<f64> = l
                .split_whitespace()
                .take(3)
                .map(|s| s.parse().unwrap())
                .collect();
            [c[0], c[1], c[2]]
        })
        .collect();
    assert_eq!(v.len(), n);
    assert!(n > 0);
    v
}

fn chroma(c: [u8; 3]) -> u8 {
    c.iter().max().unwrap() - c.iter().min().unwrap()
}

fn inside(r: &Rect, x: usize, y: usize) -> bool {
    x >= r.x && x < r.x + r.w && y >= r.y && y < r.y + r.h
}

/// Pixel bounds [x0, x1) × [y0, y1) of the coloured (cloth) pixels of a view,
/// leaving out the overlays; and how many there are.
fn cloth_pixels(
    img: &(usize, usize, Vec<[u8; 3]>),
    view: &View,
    skip: &[Rect],
) -> ([f64; 4], usize) {
    let (w, _, px) = img;
    let r = &view.rect;
    let mut b = [f64::INFINITY, f64::INFINITY, 0.0f64, 0.0f64];
    let mut n = 0;
    for y in r.y..r.y + r.h {
        for x in r.x..r.x + r.w {
            if skip.iter().any(|s| inside(s, x, y)) || chroma(px[y * w + x]) <= 12 {
                continue;
            }
            n += 1;
            b = [
                b[0].min(x as f64),
                b[1].min(y as f64),
                b[2].max(x as f64 + 1.0),
                b[3].max(y as f64 + 1.0),
            ];
        }
    }
    (b, n)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Where a view draws a point (picture pixels, continuous).
fn project(view: &View, p: [f64; 3]) -> [f64; 2] {
    let c = &view.camera;
    let d = [p[0] - c.eye[0], p[1] - c.eye[1], p[2] - c.eye[2]];
    let (x, y, z) = (dot(d, c.right), dot(d, c.up), dot(d, c.forward));
    let (u, v) = match c.projection {
        Projection::Orthographic { px_per_m } => (px_per_m * x, px_per_m * y),
        Projection::Perspective { focal_px } => {
            assert!(z > 0.0, "{p:?} is behind the camera");
            (focal_px * x / z, focal_px * y / z)
        }
    };
    [
        view.rect.x as f64 + c.centre_px[0] + u,
        view.rect.y as f64 + c.centre_px[1] - v,
    ]
}

fn projected_bounds(view: &View, pts: &[[f64; 3]]) -> [f64; 4] {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in pts {
        let q = project(view, *p);
        b = [
            b[0].min(q[0]),
            b[1].min(q[1]),
            b[2].max(q[0]),
            b[3].max(q[1]),
        ];
    }
    b
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() < 1e-12)
}

/// The views draw world axes as documented: the top view x right and y up,
/// the front view x right and z up, the perspective view from the front left
/// looking down.
fn check_cameras(v: &Views) {
    assert!(close(v.top.camera.right, [1.0, 0.0, 0.0]));
    assert!(close(v.top.camera.up, [0.0, 1.0, 0.0]));
    assert!(close(v.front.camera.right, [1.0, 0.0, 0.0]));
    assert!(close(v.front.camera.up, [0.0, 0.0, 1.0]));
    let f = v.main.camera.forward;
    assert!(
        f[0] > 0.0 && f[1] > 0.0 && (f[2] + 0.5).abs() < 1e-9,
        "{f:?}"
    );
}

/// The cloth's pixels in the top, front (if `front_view`) and perspective views cover the
/// projection of `cloth` (within 3 pixels), and the block is grey where the
/// top and front views draw it.
fn check_picture(png: &Path, cloth: &[[f64; 3]], views: &Views, front_view: bool) {
    let img = decode(png);
    assert_eq!((img.0, img.1), (1200, 800));
    // not blank: much of it differs from the white background
    let drawn = img.2.iter().filter(|c| **c != [255, 255, 255]).count();
    assert!(
        drawn as f64 > 0.08 * img.2.len() as f64,
        "{drawn} pixels drawn"
    );
    let skip = [views.legend, views.triad];
    for (name, view) in [
        ("top", &views.top),
        ("front", &views.front),
        ("perspective", &views.main),
    ] {
        if name == "front" && !front_view {
            continue;
        }
        let (seen, n) = cloth_pixels(&img, view, &skip);
        let want = projected_bounds(view, cloth);
        for k in 0..4 {
            assert!(
                (seen[k] - want[k]).abs() <= 3.0,
                "{name} view: cloth pixels span {seen:?}, the cloth projects to {want:?}"
            );
        }
        // and fill a good part of that box (a drape, not a few stray pixels)
        let area = (want[2] - want[0]) * (want[3] - want[1]);
        assert!(n as f64 > 0.3 * area, "{name} view: {n} of {area} pixels");
        // the view is framed on the scene: the cloth is large in it
        assert!(
            want[2] - want[0] > 0.2 * view.rect.w as f64,
            "{name}: {want:?}"
        );
    }
    for (view, p) in [(&views.top, BLOCK_TOP), (&views.front, BLOCK_FRONT)] {
        let q = project(view, p);
        let c = img.2[q[1] as usize * img.0 + q[0] as usize];
        assert!(
            chroma(c) <= 6 && c[0] < 240 && c[0] > 40,
            "block at {q:?}: {c:?}"
        );
    }
}

fn obstacles_of(scene: &Path) -> Vec<Surface> {
    let sc = garment_sim::scene::Scene::load(scene).unwrap();
    let sim = sc.build(&Default::default()).unwrap();
    sim.obstacles().iter().map(Surface::from_obstacle).collect()
}

#[test]
fn drape_draws_the_final_shape() {
    let dir = support::Scratch::new("pictures_drape");
    let scene = write_scene(&dir);
    let out = dir.join("out");
    let stdout = run(&["drape"], &[&scene, Path::new("--out"), &out]);
    assert!(stdout.contains("final.png"), "{stdout}");
    let cloth = read_ply(&out.join("final.ply"));
    // the layout of a picture of that cloth and the scene's (static) obstacles
    let mut p = Picture::new(
        "ball_and_block",
        Surface {
            vertices: cloth.clone(),
            triangles: Vec::new(),
        },
    );
    p.obstacles = obstacles_of(&scene);
    let views = p.views();
    check_cameras(&views);
    check_picture(&out.join("final.png"), &cloth, &views, true);
}

#[test]
fn bag_export_draws_a_frame() {
    let dir = support::Scratch::new("pictures_bag");
    let scene = write_scene(&dir);
    let (out, bag) = (dir.join("out"), dir.join("bag"));
    run(
        &["drape"],
        &[&scene, Path::new("--out"), &out, Path::new("--bag"), &bag],
    );
    for (when, name) in [(["--last", ""], "last"), (["--time", "0"], "first")] {
        let when: Vec<&str> = when.into_iter().filter(|s| !s.is_empty()).collect();
        let (png, ply) = (
            dir.join(format!("{name}.png")),
            dir.join(format!("{name}.ply")),
        );
        for (file, format) in [(&png, "png"), (&ply, "ply")] {
            let mut args = vec!["bag", "export"];
            args.extend(&when);
            args.extend(["--format", format]);
            run(&args, &[&bag, Path::new("--out"), file]);
        }
        let cloth = read_ply(&ply);
        let t = if name == "last" {
            garment_sim::bag::ExportTime::Last
        } else {
            garment_sim::bag::ExportTime::At(0.0)
        };
        let shape = garment_sim::bag::shape_at(&bag, t, "/cloth/points", "/cloth/mesh").unwrap();
        // the obstacles come from the bag's markers: the scene's two, where they are
        assert_eq!(shape.obstacles.len(), 2);
        for (a, b) in shape.obstacles.iter().zip(obstacles_of(&scene)) {
            // the same triangles (the markers hold them as a list: welded
            // back into vertices, in another order)
            assert_eq!(a.triangles.len(), b.triangles.len());
            for p in &a.vertices {
                assert!(
                    b.vertices
                        .iter()
                        .any(|v| (0..3).all(|k| (v[k] - p[k]).abs() < 1e-9)),
                    "{p:?} is not a vertex of the scene's obstacle"
                );
            }
        }
        assert_eq!(
            shape.scene.as_ref().map(|s| (s.0.as_str(), s.1)),
            Some(("ball_and_block", [21, 21]))
        );
        let views = garment_sim::bag::shape_picture(&shape).views();
        check_cameras(&views);
        // the cloth released flat is seen edge-on from the front: no pixels
        check_picture(&png, &cloth, &views, name == "last");
        if name == "first" {
            // released flat: the top view shows the 40 cm square at
            // x, y ∈ [−0.2, 0.2] m
            let img = decode(&png);
            let (seen, _) = cloth_pixels(&img, &views.top, &[views.legend]);
            let a = project(&views.top, [-0.2, 0.2, 0.3]);
            let b = project(&views.top, [0.2, -0.2, 0.3]);
            for (s, w) in seen.iter().zip([a[0], a[1], b[0], b[1]]) {
                assert!((s - w).abs() <= 2.0, "{seen:?} vs {a:?} {b:?}");
            }
            // square on the screen
            assert!(((seen[2] - seen[0]) - (seen[3] - seen[1])).abs() <= 2.0);
        }
    }
}
