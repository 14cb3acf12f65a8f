//! What the integration tests share: the binary under test
//! ([`garment_sim`]), a scratch directory per test ([`Scratch`]), running a
//! command inside a network namespace made for it ([`in_loopback_namespace`]:
//! only a loopback interface, with multicast for DDS discovery, so that no
//! packet leaves it), and the Python interoperability tests ([`pytest`],
//! failing with what to install, never passing silently).
#![allow(dead_code)] // each test file uses part of it

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The `garment_sim` binary under test, as a command to add arguments to.
pub fn garment_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_garment_sim"))
}

/// Runs `cmd`, which must succeed (else fails the test with its arguments,
/// standard output and error); returns its standard output.
pub fn stdout_of(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{:?}: {stdout}\n{}",
        cmd.get_args().collect::<Vec<_>>(),
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

/// `garment_sim COMMAND ARGS --out OUT` (a lab command: `drapemeter`,
/// `cantilever`), which must succeed: its standard output.
pub fn lab_stdout(command: &str, args: &[&str], out: &Path) -> String {
    stdout_of(garment_sim().arg(command).args(args).arg("--out").arg(out))
}

/// [`lab_stdout`] and the run's `OUT/report.json`.
pub fn lab_report(command: &str, args: &[&str], out: &Path) -> (String, serde_json::Value) {
    let stdout = lab_stdout(command, args, out);
    let rep = std::fs::read_to_string(out.join("report.json")).unwrap();
    (stdout, serde_json::from_str(&rep).unwrap())
}

/// A Cyclone DDS configuration in `dir` that keeps the participant on the
/// loopback interface, as the URI `CYCLONEDDS_URI` takes.
pub fn cyclone_loopback_uri(dir: &Path) -> std::ffi::OsString {
    let cfg = dir.join("cyclonedds.xml");
    std::fs::write(
        &cfg,
        "<CycloneDDS><Domain id=\"any\"><General><Interfaces>\
         <NetworkInterface name=\"lo\" multicast=\"true\"/>\
         </Interfaces></General></Domain></CycloneDDS>",
    )
    .unwrap();
    std::ffi::OsString::from(format!("file://{}", cfg.display()))
}

/// The binary's path.
pub fn garment_sim_path() -> &'static str {
    env!("CARGO_BIN_EXE_garment_sim")
}

/// Runs `script` with `sh -c` (with `args` as `$0`, `$1`, …) in a network
/// namespace made for it (`unshare -rn`) whose loopback interface is up and
/// routes multicast, without `ROS_DOMAIN_ID`.
pub fn in_loopback_namespace(script: &str, args: &[&OsStr]) -> Command {
    let mut c = Command::new("unshare");
    c.args(["-rn", "sh", "-c"])
        .arg(format!(
            "ip link set lo up && ip link set lo multicast on && \
             ip route add 224.0.0.0/4 dev lo && {script}"
        ))
        .args(args)
        .env_remove("ROS_DOMAIN_ID");
    c
}

/// A test's scratch directory under the system's temporary directory:
/// created empty, removed when the test passes, kept (and its path printed)
/// when it fails, for a look at what the test wrote.
pub struct Scratch(PathBuf);

impl Scratch {
    /// `garment_sim_NAME_PID`, emptied and created.
    pub fn new(name: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("garment_sim_{name}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", d.display()));
        Scratch(d)
    }
}

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("test output kept in {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Fails unless `python3 -c "import MODULES"` works.
pub fn require_python(modules: &str) {
    require_python_in(
        "python3",
        modules,
        "python3 -m pip install -r tests/requirements.txt",
    );
}

/// Fails unless `PYTHON -c "import MODULES"` works, saying `install` (the
/// command that installs them) if not.
pub fn require_python_in(python: &str, modules: &str, install: &str) {
    let probe = Command::new(python)
        .args(["-c", &format!("import {modules}")])
        .output();
    let err = match probe {
        Ok(p) if p.status.success() => return,
        Ok(p) => String::from_utf8_lossy(&p.stderr).into_owned(),
        Err(e) => format!("{python}: {e}"),
    };
    panic!("needs Python packages ({modules}) in {python}: {install}\n{err}");
}

/// Runs `python3 -m pytest FILE` (in a loopback-only network namespace if
/// `netns`) with `envs`, prints its output and asserts that it passed with
/// `expect` (e.g. "5 passed") in its output and nothing skipped.
pub fn pytest(file: &str, modules: &str, netns: bool, envs: &[(&str, &OsStr)], expect: &str) {
    require_python(modules);
    pytest_in("python3", file, netns, envs, expect);
}

/// [`pytest`] with the interpreter `python` (e.g. a venv's), whose packages
/// the caller has checked.
pub fn pytest_in(python: &str, file: &str, netns: bool, envs: &[(&str, &OsStr)], expect: &str) {
    let mut cmd = if netns {
        in_loopback_namespace(
            &format!("exec \"$0\" -m pytest -q -s -rs {file}"),
            &[OsStr::new(python)],
        )
    } else {
        let mut c = Command::new(python);
        c.args(["-m", "pytest", "-q", "-s", "-rs", file]);
        c
    };
    for (k, v) in envs {
        cmd.env(k, v);
    }
    let out = cmd
        .env_remove("ROS_DOMAIN_ID")
        .output()
        .expect("python3 (and for network tests unshare and ip) are needed");
    let text = succeeded(&out, expect);
    assert!(!text.contains("skipped"), "{text}");
}

/// A finished command's stdout and stderr together, printed; the test
/// fails unless the command succeeded and said `expect`.
pub fn succeeded(out: &std::process::Output, expect: &str) -> String {
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    assert!(out.status.success(), "{text}");
    assert!(text.contains(expect), "{text}");
    text
}

/// The shipped fabric files (`config/fabrics/*.yaml`), sorted; there are at
/// least five.
pub fn shipped_fabrics() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fabrics");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
        .collect();
    v.sort();
    assert!(v.len() >= 5, "{v:?}");
    v
}

/// A copy of a fabric with its bending rigidity B and hysteresis 2HB, warp
/// and weft, times `k`.
pub fn with_bending_scaled(f: &garment_sim::fabric::Fabric, k: f64) -> garment_sim::fabric::Fabric {
    let mut file = f.file.clone();
    for d in [&mut file.warp, &mut file.weft] {
        d.bending.b = d.bending.b.map(|b| b * k);
        d.bending.hb = d.bending.hb.map(|b| b * k);
    }
    garment_sim::io::fabric_from_file(file, Path::new("config/fabrics")).unwrap()
}

/// Whether the ray from `p` along `d` crosses the triangle `t` in front of
/// `p` (Möller–Trumbore): for inside tests by ray parity that share no code
/// with the solver's contacts.
pub fn ray_crosses(
    p: &nalgebra::Vector3<f64>,
    d: &nalgebra::Vector3<f64>,
    t: [nalgebra::Vector3<f64>; 3],
) -> bool {
    let [a, b, c] = t;
    let (e1, e2) = (b - a, c - a);
    let h = d.cross(&e2);
    let det = e1.dot(&h);
    if det.abs() < 1e-14 {
        return false;
    }
    let s = p - a;
    let u = s.dot(&h) / det;
    let q = s.cross(&e1);
    let w = d.dot(&q) / det;
    let dist = e2.dot(&q) / det;
    u >= 0.0 && w >= 0.0 && u + w <= 1.0 && dist > 0.0
}

/// Pins vertex `v` of `sim` where it is, then sends its target out of range
/// (not finite: a target no message or scene may give) during the sixth
/// step: that step fails, the five before it run.
pub fn pin_failing_at_step_6(sim: &mut garment_sim::solver::Simulation, v: usize) {
    use garment_sim::solver::{Pin, PinPath};
    let dt = sim.params().dt;
    let p0 = sim.cloth.positions()[v];
    let mut pins: Vec<Pin> = sim.pins().to_vec();
    pins.retain(|p| p.vertex != v);
    pins.push(Pin::new(
        v,
        PinPath::Waypoints(vec![
            (0.0, p0),
            (5.5 * dt, p0),
            (
                5.6 * dt,
                p0 + nalgebra::Vector3::new(f64::INFINITY, 0.0, 0.0),
            ),
        ]),
    ));
    sim.set_pins(pins).unwrap();
}

/// Width, height and number of distinct colours of an 8-bit RGB or RGBA PNG.
pub fn png_summary(path: &Path) -> (usize, usize, usize) {
    let f = std::io::BufReader::new(
        std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    );
    let mut r = png::Decoder::new(f).read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.bit_depth, png::BitDepth::Eight, "{}", path.display());
    let px = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        c => panic!("{}: colour type {c:?}", path.display()),
    };
    let colours: std::collections::HashSet<&[u8]> =
        buf[..info.buffer_size()].chunks_exact(px).collect();
    (info.width as usize, info.height as usize, colours.len())
}

/// The vertices (`v x y z`) and the largest vertex index a face (`f a/.. b/.. c/..`,
/// from 1) names in a Wavefront OBJ file.
pub fn obj_vertices(path: &Path) -> (Vec<[f64; 3]>, usize) {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut v, mut top) = (Vec::new(), 0);
    for l in text.lines() {
        let mut w = l.split_whitespace();
        match w.next() {
            Some("v") => {
                let c: Vec<f64> = w.map(|s| s.parse().unwrap()).collect();
                v.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                for c in w {
                    let i: usize = c.split('/').next().unwrap().parse().unwrap();
                    assert!(i >= 1, "{}: face index {i}", path.display());
                    top = top.max(i);
                }
            }
            _ => {}
        }
    }
    (v, top)
}

/// Checks a `body_pressure.ply` (x y z pressure force area per vertex, then
/// triangles) against itself: every vertex's area is a third of its
/// triangles' areas (computed from the positions and faces), its force is
/// its pressure times its area, pressures and forces are ≥ 0; returns the
/// vertex count and the total force, N.
pub fn check_body_pressure_ply(path: &Path) -> (usize, f64) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let (mut nv, mut nf) = (0, 0);
    for l in lines.by_ref() {
        if let Some(v) = l.strip_prefix("element vertex ") {
            nv = v.trim().parse().unwrap();
        }
        if let Some(v) = l.strip_prefix("element face ") {
            nf = v.trim().parse().unwrap();
        }
        if l == "end_header" {
            break;
        }
    }
    let rows: Vec<Vec<f64>> = lines
        .by_ref()
        .take(nv)
        .map(|l| l.split_whitespace().map(|s| s.parse().unwrap()).collect())
        .collect();
    let faces: Vec<[usize; 3]> = lines
        .take(nf)
        .map(|l| {
            let c: Vec<usize> = l.split_whitespace().map(|s| s.parse().unwrap()).collect();
            assert_eq!(c[0], 3, "{}: a face of {} vertices", path.display(), c[0]);
            [c[1], c[2], c[3]]
        })
        .collect();
    assert!(nv > 0 && rows.len() == nv && faces.len() == nf && nf > 0);
    let mut area = vec![0.0; nv];
    for t in &faces {
        let p = |k: usize| nalgebra::Vector3::new(rows[t[k]][0], rows[t[k]][1], rows[t[k]][2]);
        let a = 0.5 * (p(1) - p(0)).cross(&(p(2) - p(0))).norm();
        for &k in t {
            area[k] += a / 3.0;
        }
    }
    let total: f64 = area.iter().sum();
    let mut force = 0.0;
    for (i, r) in rows.iter().enumerate() {
        let (pressure, f, a) = (r[3], r[4], r[5]);
        // positions are written to a micrometre: areas agree to about 1e-4
        assert!(
            (a - area[i]).abs() <= 1e-4 * area[i] + 1e-12 * total,
            "{}: vertex {i}: area {a} against {} from its triangles",
            path.display(),
            area[i]
        );
        assert!(
            pressure >= 0.0 && f >= 0.0,
            "{}: vertex {i}: {r:?}",
            path.display()
        );
        assert!(
            (f - pressure * a).abs() <= 1e-5 * f.max(pressure * a) + 1e-12,
            "{}: vertex {i}: force {f} against pressure × area {}",
            path.display(),
            pressure * a
        );
        force += f;
    }
    (nv, force)
}
