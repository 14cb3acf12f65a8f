//! Bad and extreme inputs (issue 19): each is refused with exit code 1 and
//! an error naming the input and the bound, never a panic, never a result
//! with exit code 0. The bounds are those of `garment_sim::limits`.

mod support;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn bin() -> Command {
    support::garment_sim()
}

fn acrylic() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config/fabrics/acrylic.yaml")
}

/// Runs `args` and checks the refusal: exit code 1, every `needles` in the
/// error, no panic.
fn refused(args: &[&str], needles: &[&str]) {
    let o = bin().args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.code() == Some(1) || o.status.code() == Some(2),
        "{args:?}: exit {:?}, expected a refusal\n{err}",
        o.status.code()
    );
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: error lacks {n:?}: {err}");
    }
}

/// A scene: a 0.5 m cloth of 5 cm spacing at (-0.25, -0.25, 1) plus `rest`.
fn scene(dir: &Path, name: &str, cloth_extra: &str, rest: &str) -> String {
    let p = dir.join(format!("{name}.yaml"));
    std::fs::write(
        &p,
        format!(
            "cloth:\n  fabric: {}\n  size: [0.5, 0.5]\n  spacing: 0.05\n  \
             pose: {{ position: [-0.25, -0.25, 1.0] }}\n{cloth_extra}\
             dt: 0.001\nduration: 0.05\n{rest}",
            acrylic().display()
        ),
    )
    .unwrap();
    p.display().to_string()
}

#[test]
fn implausible_scene_fields_are_refused_with_the_field_named() {
    let d = support::Scratch::new("bad_scenes");
    let out = d.join("out");
    let out = out.to_str().unwrap();
    let cases: Vec<(&str, &str, &str, Vec<&str>)> = vec![
        (
            "bad_cg_tolerance",
            "",
            "cg_tolerance: 2.0\n",
            vec!["cg_tolerance = 2", "(0, 1)"],
        ),
        (
            "bad_hinges",
            "  hinges: sideways\n",
            "",
            vec!["hinges", "sideways", "mirror_symmetric"],
        ),
        (
            "nan_target",
            "",
            "pins: [ { grid: [0, 0], target: [.nan, 0, 1] } ]\n",
            vec!["pins[0].target", "not finite"],
        ),
        (
            "mm_target",
            "",
            "pins: [ { grid: [0, 0], target: [500, 0, 1000] } ]\n",
            vec!["pins[0].target", "MAX_REACH"],
        ),
        (
            "fast_pin",
            "",
            "pins: [ { grid: [0, 0], velocity: [100000, 0, 0] } ]\n",
            vec!["pins[0].velocity", "10 m/s"],
        ),
        (
            "fast_path",
            "",
            "pins: [ { grid: [0, 0], path: [ { t: 0, position: [-0.25, -0.25, 1] }, \
             { t: 0.01, position: [0.75, -0.25, 1] } ] } ]\n",
            vec!["pins[0].path[0..1] speed"],
        ),
        (
            "huge_sphere",
            "",
            "obstacles: [ { id: ball, shape: { type: sphere, radius: 1e300 }, \
             pose: { position: [0, 0, -2] } } ]\n",
            vec!["\"ball\"", "radius", "MAX_OBSTACLE_SIZE"],
        ),
        (
            "nan_velocity",
            "",
            "obstacles: [ { id: b, shape: { type: box, size: [1, 1, 0.1] }, \
             pose: { position: [0, 0, 0.5] }, linear_velocity: [.nan, 0, 0] } ]\n",
            vec!["obstacles[0].linear_velocity", "not finite"],
        ),
        (
            "inside_box",
            "",
            "obstacles: [ { id: table, shape: { type: box, size: [1, 1, 0.2] }, \
             pose: { position: [0, 0, 1.0] } } ]\n",
            vec!["\"table\"", "overlaps the cloth", "inside it"],
        ),
        (
            "inside_sphere",
            "",
            "obstacles: [ { id: ball, shape: { type: sphere, radius: 0.3 }, \
             pose: { position: [0, 0, 1.0] } } ]\n",
            vec!["\"ball\"", "overlaps the cloth", "0.3000 m inside"],
        ),
        (
            "far_table",
            "",
            "obstacles: [ { id: table, shape: { type: box, size: [1, 1, 0.1] }, \
             pose: { position: [10000, 0, 0.5] } } ]\n",
            vec!["obstacles[0] (\"table\") pose.position", "MAX_REACH"],
        ),
        (
            "mm_table",
            "",
            "obstacles: [ { id: table, shape: { type: box, size: [1.0, 0.6, 0.05] }, \
             pose: { position: [0, 0, 720] } } ]\n",
            vec!["obstacles[0] (\"table\") pose.position", "MAX_REACH"],
        ),
        (
            "far_sphere",
            "",
            "obstacles: [ { id: a, shape: { type: sphere, radius: 0.1 }, \
             pose: { position: [0, 0, 0] } }, { id: b, shape: { type: sphere, radius: 0.1 }, \
             pose: { position: [0, -5, 1] } } ]\n",
            vec!["obstacles[1] (\"b\") pose.position", "MAX_REACH"],
        ),
        (
            "thick_cloth",
            "  thickness: 1.0\n",
            "",
            vec!["cloth.thickness = 1", "0.02"],
        ),
    ];
    for (name, extra, rest, needles) in cases {
        let p = scene(&d, name, extra, rest);
        let mut want = needles.clone();
        want.push(name);
        refused(&["drape", &p, "--out", out], &want);
    }
    // a scene's dt above MAX_DT
    let p = scene(&d, "long_step", "", "");
    std::fs::write(
        &p,
        std::fs::read_to_string(&p)
            .unwrap()
            .replace("dt: 0.001", "dt: 1"),
    )
    .unwrap();
    refused(&["drape", &p, "--out", out], &["dt = 1", "0.05"]);
    assert!(!Path::new(out).join("final.ply").exists());
}

#[test]
fn implausible_command_line_values_are_refused() {
    let d = support::Scratch::new("bad_cli");
    let out = d.join("out");
    let out = out.to_str().unwrap();
    let ff = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenes/free_fall.yaml");
    let fabric = acrylic();
    let fabric = fabric.to_str().unwrap();
    let drape = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = vec!["drape".into(), ff.into(), "--out".into(), out.into()];
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let cases: Vec<(Vec<String>, Vec<&str>)> = vec![
        (drape(&["--duration", "-1"]), vec!["--duration = -1"]),
        (drape(&["--duration", "NaN"]), vec!["--duration = NaN"]),
        (drape(&["--duration", "inf"]), vec!["--duration = inf"]),
        (
            drape(&["--cg-tolerance", "NaN"]),
            vec!["--cg-tolerance = NaN"],
        ),
        (drape(&["--cg-tolerance=-1"]), vec!["--cg-tolerance = -1"]),
        (
            drape(&["--cg-tolerance", "1"]),
            vec!["--cg-tolerance = 1", "(0, 1)"],
        ),
        (drape(&["--dt", "1000"]), vec!["--dt = 1000", "0.05"]),
        (drape(&["--spacing", "-0.1"]), vec!["--spacing = -0.1"]),
        (
            [
                "trial",
                concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/config/trials/skirt_on_anny.yaml"
                ),
                "--cg-tolerance",
                "2",
                "--out",
                out,
            ]
            .map(String::from)
            .to_vec(),
            vec!["cg_tolerance = 2", "(0, 1)"],
        ),
        (
            drape(&["--hinges", "diagonal"]),
            vec!["--hinges", "diagonal", "skewed or mirror_symmetric"],
        ),
        (
            [
                "kes", fabric, "--test", "tensile", "--dt", "1000", "--out", out,
            ]
            .map(String::from)
            .to_vec(),
            vec!["dt = 1000", "0.05"],
        ),
        (
            ["drapemeter", fabric, "--dt", "1", "--out", out]
                .map(String::from)
                .to_vec(),
            vec!["dt = 1", "0.05"],
        ),
        (
            ["drapemeter", fabric, "--diameter", "-0.3", "--out", out]
                .map(String::from)
                .to_vec(),
            vec!["diameter = -0.3"],
        ),
        (
            ["drapemeter", fabric, "--duration", "NaN", "--out", out]
                .map(String::from)
                .to_vec(),
            vec!["--duration", "NaN"],
        ),
        (
            ["bench", "--steps", "0"].map(String::from).to_vec(),
            vec!["--steps", "'0'"],
        ),
        (
            ["bench", "--warmup", "NaN"].map(String::from).to_vec(),
            vec!["--warmup", "NaN"],
        ),
        (
            ["bench", "--repeat", "0"].map(String::from).to_vec(),
            vec!["--repeat", "≥ 1"],
        ),
        (
            ["bag", "export", out, "--time", "-1", "--out", out]
                .map(String::from)
                .to_vec(),
            vec!["--time", "-1"],
        ),
    ];
    for (args, needles) in cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&a, &needles);
    }
    assert!(!Path::new(out).join("final.ply").exists());
}

#[test]
fn implausible_kes_values_are_refused_with_the_range() {
    let d = support::Scratch::new("bad_kes");
    let text = std::fs::read_to_string(acrylic()).unwrap();
    let out = d.join("out");
    for (field, value, needle) in [
        ("EMT", "1000000", "tensile.EMT = 1000000"),
        ("G", "1e6", "shear.G = 1000000"),
        ("B", "1e6", "bending.B = 1000000"),
    ] {
        // the first occurrence of `field: ` (the warp direction)
        let at = text
            .find(&format!("{field}: "))
            .unwrap_or_else(|| panic!("{field} not in acrylic.yaml"));
        let end = at + text[at..].find([',', '}', '\n']).unwrap();
        let bad = format!("{}{field}: {value}{}", &text[..at], &text[end..]);
        let p = d.join(format!("{field}.yaml"));
        std::fs::write(&p, bad).unwrap();
        refused(
            &[
                "kes",
                p.to_str().unwrap(),
                "--test",
                "tensile",
                "--out",
                out.to_str().unwrap(),
            ],
            &[needle, "must lie in (0,", "measured fabrics"],
        );
    }
}

/// Output into a pipe closed by the reader ends the program quietly.
#[test]
fn a_closed_pipe_ends_quietly() {
    let d = support::Scratch::new("pipe");
    let ff = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenes/free_fall.yaml");
    let mut child = bin()
        .args(["drape", ff, "--duration", "0.01", "--out"])
        .arg(d.join("out"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take()); // the reader goes away before any output
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(!err.contains("Broken pipe"), "{err}");
    // ended by SIGPIPE, as any command-line tool (or done, if it printed
    // nothing before exiting)
    use std::os::unix::process::ExitStatusExt;
    assert!(
        o.status.signal() == Some(13) || o.status.success(),
        "{:?} {err}",
        o.status
    );
}

/// Runs the shell `script` in a mount namespace of the test's own
/// (`unshare -rm`, where it may mount a small tmpfs); its output and errors.
fn in_mount_namespace(script: &str) -> (String, String) {
    let o = Command::new("unshare")
        .args(["-rm", "sh", "-c", script])
        .output()
        .expect("unshare (util-linux) runs");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A full disk under `drape --out`: the error names the file, and no
/// truncated output is left (a tmpfs of 8 KiB in a mount namespace of the
/// test's own, `unshare -rm`).
#[test]
fn a_full_disk_names_the_file_and_leaves_no_truncated_output() {
    let ff = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenes/free_fall.yaml");
    let script = format!(
        "set -e; d=$(mktemp -d); mount -t tmpfs -o size=8k tmpfs \"$d\"; \
         if {bin} drape {ff} --duration 0.01 --out \"$d/out\"; then echo EXIT=0; \
         else echo EXIT=$?; fi; ls -A \"$d/out\" | sed 's/^/FILE /'",
        bin = support::garment_sim_path()
    );
    let (out, err) = in_mount_namespace(&script);
    assert!(out.contains("EXIT=1"), "{out}\n{err}");
    assert!(
        err.contains("cannot write") && err.contains("out/final.ply") && err.contains("No space"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    // what the run left: nothing, or whole files only (no final.ply, no
    // temporary file)
    let files: Vec<&str> = out
        .lines()
        .filter_map(|l| l.strip_prefix("FILE "))
        .collect();
    assert!(
        !files
            .iter()
            .any(|f| *f == "final.ply" || f.ends_with(".tmp")),
        "{files:?}"
    );
}

/// A full disk under `drape --bag` (the bag on an 128 KiB tmpfs, the
/// outputs elsewhere, in a mount namespace of the test's own): the run goes
/// on without the bag and writes its outputs, the same `final.ply` as a run
/// without a bag; the error names the bag's file and the exit code is 1;
/// the bag, copied where there is space, is rebuilt by `bag repair` and
/// reads in a CRC-checking reader.
#[test]
fn a_full_disk_under_the_bag_stops_the_recording_not_the_run() {
    let d = support::Scratch::new("bagdisk");
    let td = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/scenes/table_drape.yaml"
    );
    let run = "--spacing 0.05 --duration 0.3";
    let script = format!(
        "set -e; d={dir}; mkdir -p \"$d/disk\"; mount -t tmpfs -o size=128k tmpfs \"$d/disk\"; \
         if {bin} drape {td} {run} --out \"$d/out\" --bag \"$d/disk/bag\" --bag-rate 1000 \
         --bag-chunk-size 20000; then echo EXIT=0; else echo EXIT=$?; fi; \
         cp -r \"$d/disk/bag\" \"$d/copy\"",
        dir = d.display(),
        bin = support::garment_sim_path()
    );
    let (out, err) = in_mount_namespace(&script);
    assert!(out.contains("EXIT=1"), "{out}\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        err.contains("disk/bag")
            && (err.contains("bag_0.mcap") || err.contains("metadata.yaml"))
            && err.contains("No space")
            && err.contains("recording stopped at t = ")
            && err.contains("the run went on without it"),
        "{err}"
    );
    // the outputs, whole: the same final state as a run without a bag
    let o = bin()
        .args([
            "drape",
            td,
            "--spacing",
            "0.05",
            "--duration",
            "0.3",
            "--out",
        ])
        .arg(d.join("plain"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["final.ply", "energy.csv"] {
        assert_eq!(
            std::fs::read(d.join("out").join(f)).unwrap(),
            std::fs::read(d.join("plain").join(f)).unwrap(),
            "{f}"
        );
    }
    // what was recorded, with no temporary file left: rebuilt by `bag
    // repair`, read by the mcap crate
    let copy = d.join("copy");
    let mut names: Vec<String> = std::fs::read_dir(&copy)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["bag_0.mcap", "metadata.yaml"]);
    let o = bin().args(["bag", "repair"]).arg(&copy).output().unwrap();
    let rep = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{rep}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let data = std::fs::read(copy.join("bag_0.mcap")).unwrap();
    let n = log_times(&data).len();
    assert!(n >= 10, "{n} messages recovered\n{rep}");
    assert!(rep.contains(&format!("repaired: {n} messages")), "{rep}");
}

/// A step that fails names what drove it: the spring, its vertices and
/// strain (here a cloth stretched 1e20 times along warp, whose system the
/// PCG's norms cannot measure, and 1e80 times, whose forces overflow), on
/// every linear solver, and leaves the state as it was.
#[test]
fn a_failed_step_names_the_spring_and_the_strain() {
    use garment_sim::scene::{Overrides, Scene};
    use garment_sim::solver::LinearSolverKind;
    let sc = Scene::load(Path::new("config/scenes/free_fall.yaml")).unwrap();
    for (solver, stretch) in [
        LinearSolverKind::Cholesky,
        LinearSolverKind::Pcg,
        LinearSolverKind::Sgs,
        LinearSolverKind::Auto,
    ]
    .into_iter()
    .flat_map(|s| [(s, 1e20), (s, 1e80)])
    {
        let mut sim = sc
            .build(&Overrides {
                solver: Some(solver),
                ..Default::default()
            })
            .unwrap();
        sim.fabric.warp.tensile.elastic.c = [100.0, 0.0, 0.0, 100.0];
        let x0 = sim.cloth.positions()[0];
        let mut x = sim.cloth.positions().to_vec();
        for p in x.iter_mut() {
            p.x = x0.x + (p.x - x0.x) * stretch;
        }
        sim.cloth.set_positions(&x).unwrap();
        let before = (
            sim.cloth.positions().to_vec(),
            sim.cloth.velocities().to_vec(),
            sim.time,
        );
        let e = match sim.step() {
            Ok(_) => panic!("{solver:?}, stretch {stretch:e}: the step succeeded"),
            Err(e) => format!("{e:#}"),
        };
        assert!(
            e.contains("most stretched: tension spring")
                && e.contains("warp vertices")
                && e.contains(&format!("at strain {stretch:.3e}")),
            "{solver:?}, stretch {stretch:e}: {e}"
        );
        // nothing changed
        assert_eq!(
            (
                sim.cloth.positions().to_vec(),
                sim.cloth.velocities().to_vec(),
                sim.time
            ),
            before
        );
    }
}

/// A step that fails ends a drape, and what was computed before it is kept:
/// `run::drape` writes the energies up to the failed step, the last good
/// state (final.ply, final.png) and summary.json naming the step and the
/// error (`drape` prints them, then exits with the error); `run::run`, which
/// writes nothing, still returns the failure as an error.
#[test]
fn a_drape_whose_step_fails_writes_the_steps_before_it() {
    use garment_sim::run::run_on;
    use garment_sim::scene::run;
    use garment_sim::scene::{Overrides, Scene};
    let sc = Scene::load(Path::new("config/scenes/free_fall.yaml")).unwrap();
    let ov = Overrides {
        duration: Some(0.02),
        ..Default::default()
    };
    let out = support::Scratch::new("failed_drape");
    let mut sim = sc.build(&ov).unwrap();
    support::pin_failing_at_step_6(&mut sim, 0);
    let dt = sim.params().dt;
    let o = run::drape_built(&sc, &ov, sim, &mut run_on).unwrap();
    o.write(&out).unwrap();
    let (sim, s) = (o.sim, o.summary);
    let failure = s.failure.as_deref().expect("the run failed");
    // the sixth step ends past the last waypoint, where the target is not
    // finite: it fails, and the five steps before it are kept
    assert!(failure.starts_with("step 6 (t = 0.0042 s)"), "{failure}");
    assert!(failure.contains("diverged at vertex 0"), "{failure}");
    assert_eq!(s.steps, 5);
    assert!((sim.time - 5.0 * dt).abs() < 1e-12, "{}", sim.time);
    assert!(sim
        .cloth
        .positions()
        .iter()
        .all(|p| p.iter().all(|c| c.is_finite())));
    // the files: the energies from the start to the last good step, that
    // state, and the summary with the failure
    let csv = std::fs::read_to_string(out.join("energy.csv")).unwrap();
    let last: f64 = csv
        .lines()
        .last()
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((last - 5.0 * dt).abs() < 1e-12, "{csv}");
    assert!(out.join("final.ply").is_file() && out.join("final.png").is_file());
    let js: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(js["failure"].as_str(), Some(failure));
    assert_eq!(js["steps"].as_u64(), Some(5));
    // without outputs to keep, the failure is an error
    let mut sim = sc.build(&ov).unwrap();
    support::pin_failing_at_step_6(&mut sim, 0);
    let e = run::run(&mut sim, 0.02, 120.0, 0.005, &mut run_on).unwrap_err();
    assert!(format!("{e:#}").starts_with("step 6 (t = "), "{e:#}");
    // a run that goes to its end has no failure in its summary
    let mut sim = sc.build(&ov).unwrap();
    let (_, ok) = run::run(&mut sim, 0.02, 120.0, 0.005, &mut run_on).unwrap();
    assert!(ok.failure.is_none());
}

/// Byte ranges of the chunk records (opcode 0x06) of an MCAP file, walked
/// from the record headers (opcode, u64 length).
fn chunk_ranges(data: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= data.len() {
        let op = data[pos];
        let len = u64::from_le_bytes(data[pos + 1..pos + 9].try_into().unwrap()) as usize;
        let end = pos + 9 + len;
        if op == 0x06 {
            out.push((pos, end));
        }
        if op == 0x02 {
            break; // footer
        }
        pos = end;
    }
    out
}

/// Log times of the messages an MCAP reader (the `mcap` crate's, which
/// checks the chunks' CRCs) reads from `data`.
fn log_times(data: &[u8]) -> Vec<u64> {
    mcap::MessageStream::new(data)
        .unwrap()
        .map(|m| m.unwrap().log_time)
        .collect()
}

/// `bag repair` on a bag with 64 bytes flipped inside its middle chunk: it
/// keeps every message of the other chunks, before and after, keeps the
/// damaged file as a backup, reports the dropped chunk, and leaves no
/// temporary file.
#[test]
fn bag_repair_keeps_every_readable_chunk() {
    let d = support::Scratch::new("repair");
    let ff = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenes/free_fall.yaml");
    let bag = d.join("bag");
    let o = bin()
        .args([
            "drape",
            ff,
            "--duration",
            "0.5",
            "--bag-chunk-size",
            "20000",
            "--out",
        ])
        .arg(d.join("out"))
        .arg("--bag")
        .arg(&bag)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let file = bag.join("bag_0.mcap");
    let original = std::fs::read(&file).unwrap();
    let chunks = chunk_ranges(&original);
    assert!(chunks.len() >= 5, "{} chunks", chunks.len());
    let (a, b) = chunks[chunks.len() / 2];
    // the messages of that chunk, from the intact file
    let lost: Vec<u64> = {
        let rec = mcap::read::parse_record(original[a], &original[a + 9..b]).unwrap();
        let mcap::records::Record::Chunk { header, data } = rec else {
            panic!("not a chunk")
        };
        mcap::read::ChunkReader::new(header, &data)
            .unwrap()
            .filter_map(|r| match r.unwrap() {
                mcap::records::Record::Message { header, .. } => Some(header.log_time),
                _ => None,
            })
            .collect()
    };
    assert!(!lost.is_empty());
    let mut expected = log_times(&original);
    let all = expected.len();
    for t in &lost {
        let k = expected.iter().position(|x| x == t).unwrap();
        expected.remove(k);
    }
    let mut damaged = original.clone();
    let mid = (a + b) / 2;
    for x in &mut damaged[mid..mid + 64] {
        *x ^= 0xff;
    }
    std::fs::write(&file, &damaged).unwrap();
    // `bag info` names the damaged chunk, counts only what reads, and points
    // to `bag repair` (the file is finished: its footer is intact)
    let o = bin().args(["bag", "info"]).arg(&bag).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        out.contains(&format!("DAMAGED: the chunk at byte {a} does not read"))
            && out.contains("bag repair")
            && out.contains(&format!("Messages:          {}", all - lost.len()))
            && !out.contains("State:             complete"),
        "{out}"
    );
    let o = bin().args(["bag", "repair"]).arg(&bag).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        out.contains(&format!("dropped the chunk at byte {a}")),
        "{out}"
    );
    assert!(out.contains("bag_0.mcap.damaged"), "{out}");
    assert!(
        out.contains(&format!("repaired: {} messages", all - lost.len())),
        "{out}"
    );
    // the repaired file, read by a CRC-checking reader: every other message
    let repaired = std::fs::read(&file).unwrap();
    let mut got = log_times(&repaired);
    got.sort();
    expected.sort();
    assert_eq!(got, expected);
    // the damaged file kept as it was, and nothing else left behind
    assert_eq!(
        std::fs::read(bag.join("bag_0.mcap.damaged")).unwrap(),
        damaged
    );
    let mut names: Vec<String> = std::fs::read_dir(&bag)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["bag_0.mcap", "bag_0.mcap.damaged", "metadata.yaml"]);
}

/// A grid larger than the memory available is refused before anything is
/// allocated, with the estimate (the limit set to 100 MB here; by default
/// it is the machine's MemAvailable).
#[test]
fn a_grid_larger_than_memory_is_refused_with_the_estimate() {
    let d = support::Scratch::new("memory");
    let td = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/scenes/table_drape.yaml"
    );
    let o = bin()
        .env("GARMENT_SIM_MEMORY_LIMIT", "100000000")
        .args([
            "drape",
            td,
            "--spacing",
            "0.0025",
            "--duration",
            "0.001",
            "--out",
        ])
        .arg(d.join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("201 × 201 = 40401 vertices needs about 0.73 GB")
            && err.contains("0.10 GB of memory available"),
        "{err}"
    );
    // the estimate lies above what such a run uses: its peak resident size
    // (the largest of this test process's children, getrusage)
    let o = bin()
        .args(["drape", td, "--spacing", "0.005", "--duration", "0.01"])
        .args(["--solver", "cholesky", "--out"])
        .arg(d.join("out"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage fills the struct it is given
    assert_eq!(
        unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut ru) },
        0
    );
    let peak = ru.ru_maxrss as f64 * 1024.0;
    let est = garment_sim::limits::memory_estimate(101 * 101) as f64;
    assert!(peak > 0.0 && peak < est, "peak {peak} B, estimate {est} B");
}

/// A cloth whose size or spacing lies below MIN_CLOTH_SPACING (1 mm) is
/// refused when the scene is loaded or built, naming the file, the field
/// (cloth.size, cloth.spacing, --spacing, or the cells they give) and the
/// bound, instead of failing at its first step with a spring's internals;
/// a 1 cm cloth at exactly 1 mm is built.
#[test]
fn a_cloth_below_the_smallest_spacing_is_refused_naming_the_field_and_bound() {
    use garment_sim::limits::MIN_CLOTH_SPACING;
    use garment_sim::scene::{Overrides, Scene};
    let d = support::Scratch::new("min_spacing");
    let out = d.join("out").display().to_string();
    let raw = |name: &str, size: &str, spacing: &str| -> String {
        let p = d.join(format!("{name}.yaml"));
        std::fs::write(
            &p,
            format!(
                "cloth:\n  fabric: {}\n  size: {size}\n  spacing: {spacing}\n  \
                 pose: {{ position: [0, 0, 1] }}\ndt: 0.002\nduration: 0.05\n",
                acrylic().display()
            ),
        )
        .unwrap();
        p.display().to_string()
    };
    let bound = format!("≥ {MIN_CLOTH_SPACING} m");
    let tiny = raw("tiny", "[1e-9, 1e-9]", "1e-10");
    refused(
        &["drape", &tiny, "--out", &out],
        &[
            "tiny.yaml",
            "cloth.size (warp) = 1e-9 m",
            &bound,
            "MIN_CLOTH_SPACING",
        ],
    );
    let fine = raw("fine", "[0.5, 0.5]", "1e-4");
    refused(
        &["drape", &fine, "--out", &out],
        &[
            "fine.yaml",
            "cloth.spacing (warp) = 0.0001 m",
            &bound,
            "MIN_CLOTH_SPACING",
        ],
    );
    // 1.6 mm at 1 mm: two cells of 0.8 mm
    let cells = raw("cells", "[0.01, 0.0016]", "0.001");
    refused(
        &["drape", &cells, "--out", &out],
        &[
            "cells.yaml",
            "cloth.size (weft) = 0.0016 m at cloth.spacing = 0.001 m gives cells of 0.0008 m",
            "MIN_CLOTH_SPACING",
        ],
    );
    let small = raw("small", "[0.01, 0.01]", "0.001");
    refused(
        &["drape", &small, "--spacing", "5e-4", "--out", &out],
        &[
            "small.yaml",
            "--spacing (warp) = 0.0005 m",
            &bound,
            "MIN_CLOTH_SPACING",
        ],
    );
    // at the bound: built, 11 × 11 vertices
    let sim = Scene::load(Path::new(&small))
        .unwrap()
        .build(&Overrides::default())
        .unwrap();
    assert_eq!(sim.cloth.positions().len(), 121);
}

/// A scene of 400 KB of nested brackets is refused at once (before the YAML
/// parser, which takes minutes on it), naming the file and the line.
#[test]
fn deeply_nested_yaml_is_refused_before_parsing() {
    let d = support::Scratch::new("nested");
    let p = d.join("nested.yaml");
    std::fs::write(&p, format!("cloth: {}", "[".repeat(400_000))).unwrap();
    let t = std::time::Instant::now();
    refused(
        &["drape", p.to_str().unwrap()],
        &[
            "nested.yaml",
            "line 1: brackets nested deeper than 32 levels",
        ],
    );
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    let big = d.join("big.yaml");
    std::fs::write(
        &big,
        format!("name: x\ndescription: \"{}\"\n", "a".repeat(2 << 20)),
    )
    .unwrap();
    refused(
        &["drape", big.to_str().unwrap()],
        &["big.yaml", "larger than the 1048576 bytes"],
    );
    // the shipped files pass the same check
    for f in [
        "config/scenes/table_drape.yaml",
        "config/fabrics/acrylic.yaml",
    ] {
        let text = std::fs::read_to_string(f).unwrap();
        garment_sim::io::check_yaml_shape(&text).unwrap();
    }
}

/// Property: whatever `pins` and `obstacles` messages arrive (fields drawn
/// from extreme values, NaN, infinities and plausible ones, 400 messages
/// from a fixed seed), each is applied or refused, and the simulation then
/// steps without an error and with finite positions.
#[test]
fn random_extreme_messages_never_break_the_step() {
    use garment_sim::msgs;
    use garment_sim::ros::control::{apply_obstacle, apply_pin, ObstacleRegistry};
    use garment_sim::scene::{Overrides, Scene};
    use rand::{Rng, SeedableRng};
    let sc = Scene::load(Path::new("config/scenes/table_drape.yaml")).unwrap();
    let build = || {
        sc.build(&Overrides {
            spacing: Some(0.1),
            ..Default::default()
        })
        .unwrap()
    };
    let mut sim = build();
    let mut reg = ObstacleRegistry::from_sim(&sim);
    let centre = sim.cloth.positions()[sim.cloth.len() / 2];
    let pool = [
        0.0,
        1e-300,
        0.01,
        0.3,
        -0.5,
        1.0,
        3.0,
        -3.0,
        500.0,
        1e5,
        1e200,
        1e300,
        -1e300,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    let mut rng = rand::rngs::StdRng::seed_from_u64(19);
    let (mut applied, mut refused) = (0, 0);
    for case in 0..400 {
        if case % 40 == 0 {
            sim = build();
            reg = ObstacleRegistry::from_sim(&sim);
        }
        let n = sim.cloth.len() as u32;
        let val = |rng: &mut rand::rngs::StdRng, plausible: f64| -> f64 {
            if rng.random_bool(0.5) {
                rng.random_range(-plausible..plausible)
            } else {
                pool[rng.random_range(0..pool.len())]
            }
        };
        let point = |rng: &mut rand::rngs::StdRng| msgs::Point {
            x: centre.x + val(rng, 1.0),
            y: centre.y + val(rng, 1.0),
            z: centre.z + val(rng, 1.0),
        };
        let what = if rng.random_bool(0.6) {
            let k = rng.random_range(1..4usize);
            let m = msgs::Pin {
                operation: rng.random_range(0..4u8),
                vertices: (0..k).map(|_| rng.random_range(0..n + 2)).collect(),
                targets: if rng.random_bool(0.7) {
                    (0..k).map(|_| point(&mut rng)).collect()
                } else {
                    vec![]
                },
                velocities: if rng.random_bool(0.5) {
                    (0..k)
                        .map(|_| msgs::Vector3 {
                            x: val(&mut rng, 2.0),
                            y: val(&mut rng, 2.0),
                            z: val(&mut rng, 2.0),
                        })
                        .collect()
                } else {
                    vec![]
                },
                ..Default::default()
            };
            (apply_pin(&mut sim, None, &m, "world"), format!("{m:?}"))
        } else {
            let t = rng.random_range(1..5u8);
            let dims = match t {
                1 => 3,
                2 => 1,
                _ => 2,
            };
            let pose = msgs::Pose {
                position: point(&mut rng),
                ..Default::default()
            };
            let m = msgs::Obstacle {
                id: ["a", "b", "c"][rng.random_range(0..3)].into(),
                pose,
                primitives: vec![msgs::SolidPrimitive {
                    type_: t,
                    dimensions: (0..dims)
                        .map(|_| val(&mut rng, 0.3).abs())
                        .collect::<Vec<f64>>(),
                    ..Default::default()
                }],
                primitive_poses: vec![msgs::Pose::default()],
                velocity: msgs::Twist {
                    linear: msgs::Vector3 {
                        x: val(&mut rng, 1.0),
                        y: val(&mut rng, 1.0),
                        z: val(&mut rng, 1.0),
                    },
                    angular: msgs::Vector3 {
                        x: 0.0,
                        y: 0.0,
                        z: val(&mut rng, 1.0),
                    },
                },
                thickness: val(&mut rng, 0.01).abs(),
                friction: val(&mut rng, 1.0).abs(),
                operation: [0u8, 0, 1, 3][rng.random_range(0..4)],
                ..Default::default()
            };
            (
                apply_obstacle(&mut sim, &mut reg, &m, "world", 1000),
                format!("{m:?}"),
            )
        };
        match what.0 {
            Ok(_) => applied += 1,
            Err(_) => refused += 1,
        }
        for k in 0..5 {
            if let Err(e) = sim.step() {
                panic!("case {case}, step {k} after {}: {e:#}", what.1);
            }
            assert!(
                sim.cloth
                    .positions()
                    .iter()
                    .all(|p| p.iter().all(|c| c.is_finite())),
                "case {case}: non-finite position after {}",
                what.1
            );
        }
    }
    assert!(
        applied > 40 && refused > 40,
        "{applied} applied, {refused} refused"
    );
}

/// Every law of every shipped fabric (warp and weft tension, shear, warp and
/// weft bending, with their hysteresis) keeps a positive, finite step
/// tangent far outside its measured range, in both directions and from any
/// memory (a loop saturated either way, a reversal at the point itself): the
/// system matrix of a step stays positive definite whatever the strain.
#[test]
fn every_law_keeps_a_positive_tangent_outside_its_measured_range() {
    use garment_sim::fabric::{Law, LawState};
    let files = support::shipped_fabrics();
    let reach = |c: &garment_sim::fabric::kes::KesCurve| {
        c.load
            .iter()
            .chain(&c.recover)
            .map(|p| p.0.abs())
            .fold(0.0, f64::max)
    };
    let mut checked = 0;
    for f in &files {
        let fab = garment_sim::io::load_fabric(f).unwrap();
        let shear_reach = reach(&fab.warp.shear_curve).max(reach(&fab.weft.shear_curve));
        let laws: [(&str, &Law, f64); 5] = [
            (
                "warp tension",
                &fab.warp.tensile,
                reach(&fab.warp.tensile_curve),
            ),
            (
                "weft tension",
                &fab.weft.tensile,
                reach(&fab.weft.tensile_curve),
            ),
            ("shear", &fab.shear, shear_reach),
            (
                "warp bending",
                &fab.warp.bending,
                reach(&fab.warp.bending_curve),
            ),
            (
                "weft bending",
                &fab.weft.bending,
                reach(&fab.weft.bending_curve),
            ),
        ];
        for (name, law, xmax) in laws {
            assert!(xmax > 0.0, "{f:?} {name}: no measured range");
            assert!(
                !law.hysteresis.is_none() || name.contains("tension"),
                "{f:?} {name}"
            );
            // memories: fresh, and loops driven to ±xmax (saturated)
            let mut memories = vec![LawState::at(0.0)];
            for sign in [1.0, -1.0] {
                let mut st = LawState::at(0.0);
                for k in 1..=200 {
                    law.commit(&mut st, sign * xmax * k as f64 / 200.0);
                }
                memories.push(st);
            }
            for m in [1.5, 10.0, 100.0, 1e3, 1e4] {
                for sign in [1.0, -1.0] {
                    let x = sign * m * xmax;
                    let mut here = LawState::at(0.0);
                    law.commit(&mut here, x);
                    for st in memories.iter().chain([&here]) {
                        let (sig, _, tangent) = law.eval_for_step(st, x);
                        assert!(
                            sig.is_finite() && tangent.is_finite() && tangent > 0.0,
                            "{f:?} {name} at {m} × its measured range ({x:e}), memory \
                             {st:?}: σ {sig:e}, step tangent {tangent:e}"
                        );
                        let (_, elastic) = law.elastic.eval(x);
                        assert!(elastic > 0.0, "{f:?} {name} at {x:e}: {elastic:e}");
                        checked += 1;
                    }
                }
            }
        }
    }
    assert_eq!(checked, files.len() * 5 * 5 * 2 * 4);
}

/// A law written out in a fabric file (`law:`, as `fit-kes` writes it) with
/// a negative coefficient (a tangent that turns negative at large strains)
/// or a memory length of 0 is refused, naming the field.
#[test]
fn a_fabric_law_with_a_negative_tangent_is_refused() {
    let d = support::Scratch::new("neglaw");
    let base = std::fs::read_to_string(acrylic()).unwrap();
    let cases = [
        (
            "c: [100.0, 0.0, 0.0, -1.0e6]",
            "h0: 0.0, h1: 0.0, h2: 0.0, xs: 1.0",
            "warp.tensile.law.elastic.c",
        ),
        (
            "c: [100.0, 0.0, 0.0, 0.0]",
            "h0: 1.0, h1: 0.0, h2: 0.0, xs: 0.0",
            "warp.tensile.law.hysteresis",
        ),
        (
            "c: [0.0, 0.0, 0.0, 0.0]",
            "h0: 0.0, h1: 0.0, h2: 0.0, xs: 1.0",
            "warp.tensile.law.elastic.c",
        ),
    ];
    for (k, (c, h, field)) in cases.iter().enumerate() {
        // the law goes into warp.tensile
        let old = "EMT: 5.36 }";
        let law = format!("EMT: 5.36, law: {{ elastic: {{ {c} }}, hysteresis: {{ {h} }} }} }}");
        let text = base.replacen(old, &law, 1);
        assert_ne!(text, base);
        let p = d.join(format!("law{k}.yaml"));
        std::fs::write(&p, &text).unwrap();
        let e = format!("{:#}", garment_sim::io::load_fabric(&p).unwrap_err());
        assert!(e.contains(field), "{c} {h}: {e}");
    }
}

/// What a corpus case must give.
enum Expect {
    /// Exit code 1 or 2, every needle in the error.
    Refused(&'static [&'static str]),
    /// Exit code 0 and a `final.ply` (in the case's `out`) whose every
    /// number is finite and within 10 m of the origin.
    Finite,
}

/// Runs the program with `args` (in a network namespace of its own if
/// `netns`: a node must not reach the network); `None` if it was still
/// running after 60 s (a hang; it is killed).
fn run_bounded(args: &[String], netns: bool) -> Option<std::process::Output> {
    let mut cmd = if netns {
        let mut c = Command::new("unshare");
        c.arg("-rn").arg(support::garment_sim_path());
        c
    } else {
        bin()
    };
    let mut child = cmd
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return Some(child.wait_with_output().unwrap());
        }
        if t.elapsed().as_secs() > 60 {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// The corpus: bad, malformed and extreme inputs for every reader of the
/// program (scenes, fabrics, OBJ meshes, KES curves, C3D and CSV captures,
/// bags, command-line values, node parameters; the node's messages are the
/// property test above and the unit tests of `ros::control`). Each gives a
/// clean error naming the input (exit code 1 or 2, no panic), or a finite,
/// bounded result; none hangs.
#[test]
fn corpus_of_bad_inputs_gives_clean_errors_or_finite_results() {
    let d = support::Scratch::new("corpus");
    let dir = d.to_path_buf();
    let out = d.join("out");
    let out_s = out.display().to_string();
    let file = |name: &str, text: &[u8]| -> String {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    let fabric = acrylic().display().to_string();
    let fabric_text = std::fs::read_to_string(acrylic()).unwrap();
    // a valid scene with `cloth_extra` in its cloth and `rest` after it
    let sc = |name: &str, cloth_extra: &str, rest: &str| scene(&dir, name, cloth_extra, rest);
    // a scene file with the cloth's size and spacing as given
    let raw = |name: &str, size: &str, spacing: &str| {
        file(
            &format!("{name}.yaml"),
            format!("cloth:\n  fabric: {fabric}\n  size: {size}\n  spacing: {spacing}\ndt: 0.001\nduration: 0.05\n")
                .as_bytes(),
        )
    };
    // the file `path` with `from` replaced by `to`
    let edit = |path: String, from: &str, to: &str| {
        let t = std::fs::read_to_string(&path).unwrap();
        assert!(t.contains(from), "{from}");
        std::fs::write(&path, t.replacen(from, to, 1)).unwrap();
        path
    };
    let drape = |scene: String| -> Vec<String> {
        vec!["drape".into(), scene, "--out".into(), out_s.clone()]
    };
    // a scene with a mesh obstacle from `obj` 0.5 m below the cloth
    let mesh_scene = |name: &str, obj: &str| {
        sc(
            name,
            "",
            &format!(
                "obstacles: [ {{ id: m, shape: {{ type: mesh, obj: {obj} }}, \
                 pose: {{ position: [0, 0, 0.5] }} }} ]\n"
            ),
        )
    };
    // a fabric with the first `from` replaced by `to`
    let fab = |name: &str, from: &str, to: &str| -> String {
        assert!(fabric_text.contains(from), "{from}");
        file(name, fabric_text.replacen(from, to, 1).as_bytes())
    };
    let kes = |fabric: String| -> Vec<String> {
        ["kes", &fabric, "--test", "tensile", "--out", &out_s]
            .map(String::from)
            .to_vec()
    };
    // a fabric whose warp tensile behaviour is the raw curve file `csv`
    let curve_fabric = |name: &str, csv: &str| -> String {
        fab(
            name,
            "tensile: { LT: 0.65, WT: 8.71, RT: 62.0, EMT: 5.36 }",
            &format!("tensile: {{ curve: {csv} }}"),
        )
    };
    let identify = |capture: String| -> Vec<String> {
        ["identify", &capture, "--fabric", &fabric, "--out", &out_s]
            .map(String::from)
            .to_vec()
    };
    let ff = concat!(env!("CARGO_MANIFEST_DIR"), "/config/scenes/free_fall.yaml");
    let td = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/scenes/table_drape.yaml"
    );
    let cli = |a: &[&str]| -> Vec<String> { a.iter().map(|s| s.to_string()).collect() };
    let node = |a: &[&str]| -> Vec<String> {
        let mut v = cli(&["node", "--ros-args", "-p", &format!("scene:={ff}")]);
        v.extend(cli(a));
        v
    };
    let junk: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let c3d_header = {
        // a C3D whose header points at a parameter block past the end
        let mut h = vec![0u8; 512];
        h[0] = 2;
        h[1] = 0x50;
        h
    };
    let bag_dir = d.join("emptybag");
    std::fs::create_dir_all(&bag_dir).unwrap();
    let bag_dir = bag_dir.display().to_string();
    let magic_only = file("magic.mcap", b"\x89MCAP0\r\n");
    let garbage_mcap = file("garbage.mcap", &junk);
    use Expect::*;
    #[rustfmt::skip]
    let cases: Vec<(&str, Vec<String>, Expect)> = vec![
        // scenes
        ("scene: unclosed bracket", drape(file("s1.yaml", b"cloth: [unclosed")), Refused(&["s1.yaml"])),
        ("scene: empty", drape(file("s2.yaml", b"")), Refused(&["s2.yaml"])),
        ("scene: binary", drape(file("s3.yaml", &junk)), Refused(&["s3.yaml"])),
        ("scene: unknown field", drape(sc("s4", "", "colour: red\n")), Refused(&["s4.yaml", "colour"])),
        ("scene: missing fabric", drape(file("s5.yaml", b"cloth:\n  fabric: nofabric.yaml\n  size: [0.5, 0.5]\n  spacing: 0.05\ndt: 0.001\nduration: 0.05\n")), Refused(&["nofabric.yaml"])),
        ("scene: negative size", drape(raw("s6", "[-0.5, 0.5]", "0.05")), Refused(&["s6.yaml", "size"])),
        ("scene: spacing 0", drape(raw("s7", "[0.5, 0.5]", "0")), Refused(&["s7.yaml", "spacing"])),
        ("scene: spacing NaN", drape(raw("s7b", "[0.5, 0.5]", ".nan")), Refused(&["s7b.yaml", "spacing"])),
        ("scene: gravity NaN", drape(sc("s8", "", "gravity: [0, 0, .nan]\n")), Refused(&["s8.yaml", "gravity"])),
        ("scene: gravity 1e300", drape(sc("s8b", "", "gravity: [0, 0, -1e300]\n")), Refused(&["s8b.yaml", "gravity", "MAX_GRAVITY"])),
        ("scene: gravity 1e3", drape(sc("s8c", "", "gravity: [0, 1000, 0]\n")), Refused(&["s8c.yaml", "gravity", "MAX_GRAVITY"])),
        ("scene: duration -1", drape(edit(sc("s9", "", ""), "duration: 0.05", "duration: -1")), Refused(&["s9.yaml", "duration"])),
        ("scene: dt NaN", drape(edit(sc("s9b", "", ""), "dt: 0.001", "dt: .nan")), Refused(&["s9b.yaml", "dt"])),
        ("scene: pin grid outside", drape(sc("s10", "", "pins: [ { grid: [100, 0] } ]\n")), Refused(&["s10.yaml", "pins[0].grid"])),
        ("scene: pin vertex outside", drape(sc("s11", "", "pins: [ { vertex: 99999 } ]\n")), Refused(&["s11.yaml", "pins[0].vertex"])),
        ("scene: release_at -1", drape(sc("s12", "", "pins: [ { grid: [0, 0], release_at: -1 } ]\n")), Refused(&["s12.yaml", "release_at"])),
        ("scene: empty path", drape(sc("s13", "", "pins: [ { grid: [0, 0], path: [] } ]\n")), Refused(&["s13.yaml", "pins[0].path"])),
        ("scene: waypoint time NaN", drape(sc("s14", "", "pins: [ { grid: [0, 0], path: [ { t: .nan, position: [-0.25, -0.25, 1] } ] } ]\n")), Refused(&["s14.yaml", "pins[0].path[0].t"])),
        ("scene: waypoints back in time", drape(sc("s15", "", "pins: [ { grid: [0, 0], path: [ { t: 1, position: [-0.25, -0.25, 1] }, { t: 0.5, position: [-0.25, -0.25, 1.1] } ] } ]\n")), Refused(&["s15.yaml", "waypoint times"])),
        ("scene: duplicate obstacle id", drape(sc("s16", "", "obstacles: [ { id: a, shape: { type: sphere, radius: 0.1 }, pose: { position: [0, 0, 0.5] } }, { id: a, shape: { type: sphere, radius: 0.1 }, pose: { position: [0, 0, 0.2] } } ]\n")), Refused(&["s16.yaml", "duplicate"])),
        ("scene: unknown shape", drape(sc("s17", "", "obstacles: [ { id: t, shape: { type: torus, radius: 0.1 } } ]\n")), Refused(&["s17.yaml", "torus"])),
        ("scene: place_on unknown", drape(sc("s18", "  place_on: { obstacle: nope, corner: [0, 0], gap: 0.01 }\n", "")), Refused(&["s18.yaml", "nope"])),
        ("scene: place_on a sphere", drape(sc("s19", "  place_on: { obstacle: b, corner: [0, 0], gap: 0.01 }\n", "obstacles: [ { id: b, shape: { type: sphere, radius: 0.1 }, pose: { position: [0, 0, 0.5] } } ]\n")), Refused(&["s19.yaml", "must be a box"])),
        ("scene: friction 1e6", drape(sc("s20", "", "obstacles: [ { id: b, shape: { type: sphere, radius: 0.1 }, pose: { position: [0, 0, 0.5] }, friction: 1e6 } ]\n")), Refused(&["s20.yaml", "friction"])),
        ("scene: obstacle thickness 5 m", drape(sc("s21", "", "obstacles: [ { id: b, shape: { type: sphere, radius: 0.1 }, pose: { position: [0, 0, 0.5] }, thickness: 5 } ]\n")), Refused(&["s21.yaml", "thickness"])),
        ("scene: cone radius -1", drape(sc("s22", "", "obstacles: [ { id: c, shape: { type: cone, height: 0.2, radius: -1 }, pose: { position: [0, 0, 0.5] } } ]\n")), Refused(&["s22.yaml", "radius"])),
        ("scene: capsule length NaN", drape(sc("s23", "", "obstacles: [ { id: c, shape: { type: capsule, length: .nan, radius: 0.1 }, pose: { position: [0, 0, 0.5] } } ]\n")), Refused(&["s23.yaml", "length"])),
        ("scene: cylinder height inf", drape(sc("s24", "", "obstacles: [ { id: c, shape: { type: cylinder, height: .inf, radius: 0.1 }, pose: { position: [0, 0, 0.5] } } ]\n")), Refused(&["s24.yaml", "height"])),
        ("scene: spinning 1e4 rad/s", drape(sc("s25", "", "obstacles: [ { id: b, shape: { type: sphere, radius: 0.1 }, pose: { position: [0, 0, 0.5] }, angular_velocity: [0, 0, 1e4] } ]\n")), Refused(&["s25.yaml", "angular_velocity"])),
        ("scene: normal zero", drape(sc("s26", "", "obstacles: [ { id: b, shape: { type: box, size: [0.1, 0.1, 0.1] }, pose: { position: [0, 0, 0.5], normal: [0, 0, 0] } } ]\n")), Refused(&["s26.yaml", "normal"])),
        ("scene: hysteresis not a bool", drape(sc("s27", "  hysteresis: maybe\n", "")), Refused(&["s27.yaml", "hysteresis"])),
        ("scene: output_rate -1", drape(sc("s28", "", "output_rate: -1\n")), Refused(&["s28.yaml", "output_rate"])),
        ("scene: cloth 1e6 m wide", drape(file("s29.yaml", format!("cloth:\n  fabric: {fabric}\n  size: [1e6, 1e6]\n  spacing: 0.01\ndt: 0.001\nduration: 0.05\n").as_bytes())), Refused(&["s29.yaml"])),
        ("scene: mesh scale 0", drape(sc("s30", "", "obstacles: [ { id: m, shape: { type: mesh, obj: cube.obj, scale: 0 }, pose: { position: [0, 0, 0.5] } } ]\n")), Refused(&["s30.yaml", "scale"])),
        // OBJ meshes
        ("obj: missing file", drape(mesh_scene("o1", "none.obj")), Refused(&["none.obj"])),
        ("obj: empty", { file("o2.obj", b""); drape(mesh_scene("o2", "o2.obj")) }, Refused(&["o2.obj"])),
        ("obj: letters", { file("o3.obj", b"v a b c\nf 1 2 3\n"); drape(mesh_scene("o3", "o3.obj")) }, Refused(&["o3.obj"])),
        ("obj: face index outside", { file("o4.obj", b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 9\n"); drape(mesh_scene("o4", "o4.obj")) }, Refused(&["o4.obj"])),
        ("obj: NaN vertex", { file("o5.obj", b"v nan 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n"); drape(mesh_scene("o5", "o5.obj")) }, Refused(&["o5.obj"])),
        ("obj: vertex 1e6 m away", { file("o6.obj", b"v 1e6 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n"); drape(mesh_scene("o6", "o6.obj")) }, Refused(&["MAX_OBSTACLE_SIZE"])),
        ("obj: binary", { file("o7.obj", &junk); drape(mesh_scene("o7", "o7.obj")) }, Refused(&["o7.obj"])),
        ("obj: face index 0", { file("o8.obj", b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 0 1 2\n"); drape(mesh_scene("o8", "o8.obj")) }, Refused(&["o8.obj"])),
        // fabrics
        ("fabric: binary", kes(file("f1.yaml", &junk)), Refused(&["f1.yaml"])),
        ("fabric: areal mass 0", kes(fab("f2.yaml", "areal_mass_mg_per_cm2: 21.3", "areal_mass_mg_per_cm2: 0")), Refused(&["f2.yaml", "areal_mass"])),
        ("fabric: areal mass NaN", kes(fab("f3.yaml", "areal_mass_mg_per_cm2: 21.3", "areal_mass_mg_per_cm2: .nan")), Refused(&["f3.yaml", "areal_mass"])),
        ("fabric: areal mass missing", kes(fab("f4.yaml", "areal_mass_mg_per_cm2: 21.3", "")), Refused(&["f4.yaml", "areal_mass"])),
        ("fabric: damping > 0", kes(fab("f5.yaml", "alpha: -7.0", "alpha: 7.0")), Refused(&["f5.yaml", "damping.alpha"])),
        ("fabric: LT 3", kes(fab("f6.yaml", "LT: 0.65", "LT: 3")), Refused(&["f6.yaml", "LT"])),
        ("fabric: RT 200", kes(fab("f7.yaml", "RT: 62.0", "RT: 200")), Refused(&["f7.yaml", "RT"])),
        ("fabric: unknown field", kes(fab("f8.yaml", "areal_mass_mg_per_cm2: 21.3", "areal_mass_mg_per_cm2: 21.3\ncolour: red")), Refused(&["f8.yaml", "colour"])),
        ("fabric: EMT negative", kes(fab("f9.yaml", "EMT: 5.36", "EMT: -5")), Refused(&["f9.yaml", "EMT"])),
        ("fabric: G NaN", kes(fab("f10.yaml", "G: 0.80", "G: .nan")), Refused(&["f10.yaml", "shear.G"])),
        ("fabric: B 0", kes(fab("f11.yaml", "B: 0.080", "B: 0")), Refused(&["f11.yaml", "bending.B"])),
        ("fabric: missing file", kes(dir.join("nofabric.yaml").display().to_string()), Refused(&["nofabric.yaml"])),
        // KES curves
        ("kes curve: missing file", kes(curve_fabric("k1.yaml", "nocurve.csv")), Refused(&["nocurve.csv"])),
        ("kes curve: empty", { file("k2.csv", b""); kes(curve_fabric("k2.yaml", "k2.csv")) }, Refused(&["k2.csv"])),
        ("kes curve: letters", { file("k3.csv", b"x,y,branch\na,b,load\n"); kes(curve_fabric("k3.yaml", "k3.csv")) }, Refused(&["k3.csv"])),
        ("kes curve: NaN", { file("k4.csv", b"x,y,branch\n0,0,load\nnan,1,load\n0.05,500,load\n0.05,500,recover\n0,0,recover\n"); kes(curve_fabric("k4.yaml", "k4.csv")) }, Refused(&["k4.csv"])),
        ("kes curve: binary", { file("k5.csv", &junk); kes(curve_fabric("k5.yaml", "k5.csv")) }, Refused(&["k5.csv"])),
        ("fit-kes: letters", cli(&["fit-kes", &file("fk1.csv", b"direction,test,x,y,branch\nwarp,tensile,a,b,load\n"), "--areal-mass", "20", "--out", &dir.join("fk1.yaml").display().to_string()]), Refused(&["fk1.csv"])),
        ("fit-kes: empty", cli(&["fit-kes", &file("fk2.csv", b""), "--areal-mass", "20", "--out", &dir.join("fk2.yaml").display().to_string()]), Refused(&["fk2.csv"])),
        ("fit-kes: areal mass NaN", cli(&["fit-kes", &file("fk3.csv", b"direction,test,x,y,branch\n"), "--areal-mass", "NaN", "--out", &dir.join("fk3.yaml").display().to_string()]), Refused(&["fk3.csv"])),
        // captures
        ("capture: missing file", identify(dir.join("none.c3d").display().to_string()), Refused(&["none.c3d"])),
        ("capture: C3D of junk", identify(file("c1.c3d", &junk)), Refused(&["c1.c3d"])),
        ("capture: C3D empty", identify(file("c2.c3d", b"")), Refused(&["c2.c3d"])),
        ("capture: C3D header only", identify(file("c3.c3d", &c3d_header)), Refused(&["c3.c3d"])),
        ("capture: CSV header only", identify(file("c4.csv", b"frame,time,m0_x,m0_y,m0_z\n")), Refused(&["c4.csv"])),
        ("capture: CSV letters", identify(file("c5.csv", b"frame,time,m0_x,m0_y,m0_z\n0,a,b,c,d\n")), Refused(&["c5.csv"])),
        ("capture: CSV NaN", identify(file("c6.csv", b"frame,time,m0_x,m0_y,m0_z\n0,0,nan,0,0\n1,0.01,0,0,0\n")), Refused(&["c6.csv"])),
        ("capture: CSV times back", identify(file("c7.csv", b"frame,time,m0_x,m0_y,m0_z\n0,0.02,0,0,0\n1,0.01,0,0,0\n2,0.03,0,0,0\n")), Refused(&["c7.csv"])),
        // bags
        ("bag info: missing", cli(&["bag", "info", &dir.join("nobag").display().to_string()]), Refused(&["nobag"])),
        ("bag info: empty directory", cli(&["bag", "info", &bag_dir]), Refused(&["emptybag"])),
        ("bag info: junk file", cli(&["bag", "info", &garbage_mcap]), Refused(&["garbage.mcap"])),
        ("bag export: junk file", cli(&["bag", "export", &garbage_mcap, "--time", "0", "--out", &dir.join("shape.ply").display().to_string()]), Refused(&["garbage.mcap"])),
        ("bag repair: junk file", cli(&["bag", "repair", &garbage_mcap]), Refused(&["garbage.mcap"])),
        ("bag export: magic only", cli(&["bag", "export", &magic_only, "--time", "0", "--out", &dir.join("shape2.ply").display().to_string()]), Refused(&["magic.mcap"])),
        ("bag export: format xyz", cli(&["bag", "export", &magic_only, "--format", "xyz", "--out", &out_s]), Refused(&["xyz"])),
        // command-line values
        ("drape: missing scene", cli(&["drape", &dir.join("none.yaml").display().to_string()]), Refused(&["none.yaml"])),
        ("drape: --spacing abc", cli(&["drape", ff, "--spacing", "abc"]), Refused(&["--spacing"])),
        ("drape: --dt 1e999", cli(&["drape", ff, "--dt", "1e999", "--out", &out_s]), Refused(&["--dt"])),
        ("drape: --threads 100000", cli(&["drape", ff, "--threads", "100000", "--out", &out_s]), Refused(&["threads"])),
        ("drape: --solver foo", cli(&["drape", ff, "--solver", "foo"]), Refused(&["foo"])),
        ("drape: --spacing 1e-9", cli(&["drape", ff, "--spacing", "1e-9", "--out", &out_s]), Refused(&["vertices"])),
        ("kes: --test bogus", cli(&["kes", &fabric, "--test", "bogus", "--out", &out_s]), Refused(&["bogus"])),
        ("drapemeter: --diameter 0", cli(&["drapemeter", &fabric, "--diameter", "0", "--out", &out_s]), Refused(&["diameter"])),
        ("bench: --steps abc", cli(&["bench", "--steps", "abc"]), Refused(&["--steps"])),
        ("identify: --grid 0x0", cli(&["identify", &file("c8.csv", b"frame,time,m0_x,m0_y,m0_z\n"), "--fabric", &fabric, "--grid", "0x0", "--out", &out_s]), Refused(&["grid"])),
        ("identify: --spacing -1", cli(&["identify", &file("c9.csv", b"frame,time,m0_x,m0_y,m0_z\n"), "--fabric", &fabric, "--spacing", "-1", "--out", &out_s]), Refused(&["--spacing -1: must be > 0"])),
        ("fit-kes: --areal-mass -5", cli(&["fit-kes", &file("fk4.csv", b"direction,test,x,y,branch\n"), "--areal-mass", "-5", "--out", &dir.join("fk4.yaml").display().to_string()]), Refused(&["fk4.csv"])),
        // node parameters (refused before DDS starts; in a namespace without network all the same)
        ("node: publish_rate -1", node(&["-p", "publish_rate:=-1.0"]), Refused(&["publish_rate"])),
        ("node: dt 1", node(&["-p", "dt:=1.0"]), Refused(&["dt"])),
        ("node: spacing -1", node(&["-p", "spacing:=-1.0"]), Refused(&["spacing"])),
        ("node: missing scene", cli(&["node", "--ros-args", "-p", &format!("scene:={}", dir.join("none.yaml").display())]), Refused(&["none.yaml"])),
        ("node: solver foo", node(&["-p", "solver:=foo"]), Refused(&["solver"])),
        ("node: unknown parameter", node(&["-p", "colour:=1"]), Refused(&["colour"])),
        ("node: duration NaN", node(&["-p", "duration:=.nan"]), Refused(&["duration"])),
        ("node: params file missing", node(&["--params-file", &dir.join("nop.yaml").display().to_string()]), Refused(&["nop.yaml"])),
        ("node: params file junk", node(&["--params-file", &file("p1.yaml", &junk)]), Refused(&["p1.yaml"])),
        ("node: threads -1", node(&["-p", "threads:=-1"]), Refused(&["threads"])),
        ("node: max_messages_per_step 0", node(&["-p", "max_messages_per_step:=0"]), Refused(&["max_messages_per_step"])),
        // accepted extremes: finite, bounded results
        ("drape: 25 cm grid", cli(&["drape", td, "--spacing", "0.25", "--duration", "0.05", "--out", &out_s]), Finite),
        ("drape: dt at MAX_DT", cli(&["drape", ff, "--dt", "0.05", "--duration", "0.5", "--out", &out_s]), Finite),
        ("drape: cloth 2 cm thick", drape(sc("e1", "  thickness: 0.02\n", "")), Finite),
        ("drape: far pin target, travelled", drape(sc("e2", "", "pins: [ { grid: [0, 0], target: [1.5, -0.25, 1] } ]\n")), Finite),
    ];
    let n = cases.len();
    let mut failed = Vec::new();
    for (what, args, expect) in cases {
        let _ = std::fs::remove_dir_all(&out);
        let netns = args.first().is_some_and(|a| a == "node");
        let Some(o) = run_bounded(&args, netns) else {
            failed.push(format!("{what}: still running after 60 s (a hang)"));
            continue;
        };
        let err = String::from_utf8_lossy(&o.stderr);
        if err.contains("panicked") {
            failed.push(format!("{what}: panicked: {err}"));
            continue;
        }
        match expect {
            Refused(needles) => {
                if !matches!(o.status.code(), Some(1) | Some(2)) {
                    failed.push(format!(
                        "{what}: exit {:?}, expected a refusal: {err}",
                        o.status
                    ));
                }
                for needle in needles {
                    if !err.contains(needle) {
                        failed.push(format!("{what}: the error lacks {needle:?}: {err}"));
                    }
                }
            }
            Finite => {
                if !o.status.success() {
                    failed.push(format!("{what}: exit {:?}: {err}", o.status));
                    continue;
                }
                let ply = std::fs::read_to_string(out.join("final.ply")).unwrap();
                let body = ply.split("end_header\n").nth(1).unwrap();
                let mut count = 0;
                for line in body.lines().filter(|l| !l.starts_with("3 ")) {
                    for v in line.split_whitespace() {
                        let v: f64 = v.parse().unwrap();
                        if !(v.is_finite() && v.abs() < 10.0) {
                            failed.push(format!("{what}: {v} in final.ply"));
                        }
                        count += 1;
                    }
                }
                if count == 0 {
                    failed.push(format!("{what}: an empty final.ply"));
                }
            }
        }
    }
    assert!(
        failed.is_empty(),
        "{} of {n} cases:\n{}",
        failed.len(),
        failed.join("\n")
    );
    assert!(n >= 80, "{n} cases");
}
