//! A drape as a glTF 2.0 scene (`garment_sim::pictures::glb`, what `trial` writes as
//! `trial.glb`), checked by readers that are not ours: the Khronos glTF
//! validator (npm `gltf-validator`, run by tests/gltf/validate.mjs) must
//! report no error, and tests/glb_trimesh.py loads the file in trimesh and
//! reads its accessors with NumPy (vertex counts, the garment's first and
//! last frames, the animation's keys, the stretch colours).
//!
//! Needs `npm ci --prefix tests/gltf` and the Python packages of
//! tests/requirements.txt (trimesh, numpy, pytest).

mod support;
use garment_sim::pictures::glb::{write_glb, GlbScene};
use garment_sim::pictures::render::{full_scale, Surface};
use garment_sim::run::Control;
use garment_sim::scene::run;
use garment_sim::scene::{Overrides, Scene};
use std::path::Path;
use std::process::Command;

/// The shipped board drape (config/scenes/table_drape.yaml) for 0.3 s,
/// the cloth recorded every 0.025 s: the scene the tests write.
struct Drape {
    frames: Vec<(f64, Vec<[f32; 3]>)>,
    triangles: Vec<[usize; 3]>,
    body: Surface,
    stretch: Vec<f64>,
}

fn drape() -> Drape {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenes/table_drape.yaml");
    let scene = Scene::load(&path).unwrap();
    let ov = Overrides::default();
    let mut sim = scene.build(&ov).unwrap();
    let dt = sim.params().dt;
    let every = (0.025 / dt).round() as u64;
    let mut frames = Vec::new();
    let mut step = 0u64;
    run::run_to_failure(&mut sim, 0.3, 30.0, 0.0, &mut |s| {
        let s = s.sim;
        if step.is_multiple_of(every) {
            let x = s
                .cloth
                .positions()
                .iter()
                .map(|p| [p.x as f32, p.y as f32, p.z as f32]);
            frames.push((s.time, x.collect()));
        }
        step += 1;
        Ok(Control::Continue)
    })
    .unwrap();
    assert_eq!(frames.len(), 13, "frames at 0, 0.025, …, 0.3 s");
    Drape {
        frames,
        triangles: sim.cloth.triangles.clone(),
        body: Surface::from_obstacle(&sim.obstacles()[0]),
        stretch: garment_sim::msgs::publish::vertex_strain(&sim),
    }
}

/// Writes the drape as `trial.glb` in `dir` and what the readers must find
/// as `expected.json`; the GLB's path.
fn write(d: &Drape, dir: &Path) -> std::path::PathBuf {
    let body_triangles: Vec<[u32; 3]> = d
        .body
        .triangles
        .iter()
        .map(|t| t.map(|i| i as u32))
        .collect();
    let stretch_full = full_scale(&d.stretch, 0.001);
    let scene = GlbScene {
        body_vertices: &d.body.vertices,
        body_triangles: &body_triangles,
        garment_triangles: &d.triangles,
        frames: &d.frames,
        stretch: &d.stretch,
        stretch_full,
        name: "table_drape",
    };
    let glb = dir.join("trial.glb");
    write_glb(&scene, &glb).unwrap();
    let expected = serde_json::json!({
        "garment_vertices": d.frames[0].1.len(),
        "garment_triangles": d.triangles,
        "body_vertices": d.body.vertices,
        "body_triangles": body_triangles,
        "times": d.frames.iter().map(|f| f.0).collect::<Vec<_>>(),
        "first": d.frames[0].1,
        "last": d.frames.last().unwrap().1,
        "stretch": d.stretch,
        "stretch_full": stretch_full,
    });
    std::fs::write(dir.join("expected.json"), expected.to_string()).unwrap();
    glb
}

/// The Khronos validator's report on `file` (issues and info).
fn validate(file: &Path) -> serde_json::Value {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gltf");
    assert!(
        root.join("node_modules/gltf-validator").is_dir(),
        "needs the npm package gltf-validator: npm ci --prefix tests/gltf"
    );
    let out = Command::new("node")
        .arg(root.join("validate.mjs"))
        .arg(file)
        .output()
        .expect("node is needed for the glTF validator");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn a_drape_as_glb_passes_the_khronos_validator_and_loads_in_trimesh() {
    let dir = support::Scratch::new("glb");
    let d = drape();
    let glb = write(&d, &dir);

    let report = validate(&glb);
    let issues = &report["issues"];
    println!("validator {}: {issues:#}", report["validatorVersion"]);
    assert_eq!(issues["numErrors"], 0, "{issues:#}");
    assert_eq!(issues["numWarnings"], 0, "{issues:#}");
    // the validator's own count of what it read
    let info = &report["info"];
    assert_eq!(info["animationCount"], 1, "{info:#}");
    assert_eq!(info["drawCallCount"], 2, "{info:#}");
    assert_eq!(
        info["totalVertexCount"],
        d.frames[0].1.len() + d.body.vertices.len(),
        "{info:#}"
    );
    assert_eq!(
        info["totalTriangleCount"],
        d.triangles.len() + d.body.triangles.len(),
        "{info:#}"
    );

    let (glb_env, expect_env) = (
        glb.into_os_string(),
        dir.join("expected.json").into_os_string(),
    );
    support::pytest(
        "tests/glb_trimesh.py",
        "trimesh, numpy",
        false,
        &[("GLB_FILE", &glb_env), ("GLB_EXPECTED", &expect_env)],
        "4 passed",
    );
}

#[test]
fn a_scene_with_a_nan_is_refused_naming_it_and_writes_nothing() {
    let dir = support::Scratch::new("glb_nan");
    let mut frames: Vec<(f64, Vec<[f32; 3]>)> = (0..3)
        .map(|k| {
            (
                0.5 * k as f64,
                vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]],
            )
        })
        .collect();
    frames[2].1[1][2] = f32::NAN;
    let scene = GlbScene {
        body_vertices: &[],
        body_triangles: &[],
        garment_triangles: &[[0, 1, 2]],
        frames: &frames,
        stretch: &[0.0; 3],
        stretch_full: 0.1,
        name: "nan",
    };
    let path = dir.join("trial.glb");
    let e = format!("{:#}", write_glb(&scene, &path).unwrap_err());
    assert!(e.contains(&path.display().to_string()), "{e}");
    assert!(
        e.contains("garment frame 2 (t = 1 s), vertex 1: position [1.0, 0.0, NaN]"),
        "{e}"
    );
    assert!(!path.exists());
    assert_eq!(
        std::fs::read_dir(&*dir).unwrap().count(),
        0,
        "no file left behind"
    );
}

/// `garment_sim trial` writes its run as `trial.glb` (the shipped skirt at
/// 3 cm, sewing and 0.3 s of drape): the validator reports no error and
/// counts the garment's vertices as `garment.ply` has them plus the body's,
/// with one animation; trimesh loads the garment with that vertex count and
/// the body with the rest.
#[test]
fn the_trial_writes_its_run_as_a_glb_that_the_validator_and_trimesh_read() {
    let dir = support::Scratch::new("trial_glb");
    let out = support::garment_sim()
        .args(["trial", "config/trials/skirt_on_anny.yaml"])
        .args(["--spacing", "0.03", "--max-time", "0.3", "--out"])
        .arg(&*dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ply = std::fs::read(dir.join("garment.ply")).unwrap();
    let head = String::from_utf8_lossy(&ply[..ply.len().min(2000)]).to_string();
    let n: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .expect("garment.ply's vertex count")
        .trim()
        .parse()
        .unwrap();
    let glb = dir.join("trial.glb");
    let report = validate(&glb);
    let (issues, info) = (&report["issues"], &report["info"]);
    assert_eq!(issues["numErrors"], 0, "{issues:#}");
    assert_eq!(info["animationCount"], 1, "{info:#}");
    let total = info["totalVertexCount"].as_u64().unwrap() as usize;
    assert!(total > n, "garment {n} vertices plus the body's: {total}");
    let script = format!(
        "import trimesh\n\
         s = trimesh.load({glb:?}, process=False)\n\
         g = s.geometry['garment']\n\
         assert len(g.vertices) == {n}, len(g.vertices)\n\
         b = s.geometry['body']\n\
         assert len(g.vertices) + len(b.vertices) == {total}, len(b.vertices)\n\
         print('garment', len(g.vertices), 'body', len(b.vertices))\n",
        glb = glb.display().to_string()
    );
    support::require_python("trimesh");
    let py = Command::new("python3")
        .args(["-c", &script])
        .output()
        .expect("python3 with trimesh");
    assert!(
        py.status.success(),
        "{}{}",
        String::from_utf8_lossy(&py.stdout),
        String::from_utf8_lossy(&py.stderr)
    );
}
