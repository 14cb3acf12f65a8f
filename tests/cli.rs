//! The command line a newcomer runs: outputs exist and say what they should.

mod support;

fn tmp(name: &str) -> support::Scratch {
    support::Scratch::new(&format!("cli_{name}"))
}

/// `drape` of the shipped free fall for 0.2 s into the scratch `name`, with
/// `extra` arguments: it succeeds; its output directory, standard output and
/// summary.json.
fn free_fall(name: &str, extra: &[&str]) -> (support::Scratch, String, serde_json::Value) {
    let out = tmp(name);
    let o = support::garment_sim()
        .args(["drape", "config/scenes/free_fall.yaml", "--duration", "0.2"])
        .args(extra)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let s =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    (out, stdout, s)
}

#[test]
fn drape_writes_ply_energy_and_summary() {
    let (out, stdout, s) = free_fall("drape", &[]);
    for key in [
        "ms/step",
        "real-time factor",
        "settle time",
        "solver iters",
        "final energies",
    ] {
        assert!(stdout.contains(key), "summary lacks {key}: {stdout}");
    }
    assert_eq!(s["steps"], 240); // dt = 1/1200 s
                                 // which solve gave each step's answer (`auto` chooses per step: the
                                 // block-Jacobi PCG while it is cheap, else the multigrid)
    let by = &s["steps_solved_by"];
    let n = |k: &str| by[k].as_u64().unwrap();
    assert_eq!(n("pcg") + n("sgs") + n("amg") + n("cholesky"), 240, "{by}");
    assert!(n("pcg") > 0 && n("amg") > 0 && n("sgs") == 0, "{by}");
    let line = format!(
        "(steps solved by the block-Jacobi PCG {}, the Gauss–Seidel PCG 0, the multigrid {}, the Cholesky {})",
        n("pcg"),
        n("amg"),
        n("cholesky")
    );
    assert!(stdout.contains(&line), "{stdout}");
    // `--solver sgs`: every step on the Gauss–Seidel PCG, counted as such
    // (they were once counted as the block-Jacobi PCG's)
    let (_, sgs_out, t) = free_fall("drape_sgs", &["--solver", "sgs"]);
    assert_eq!(
        (
            &t["steps_solved_by"]["sgs"],
            &t["steps_solved_by"]["pcg"],
            &t["linear_solver"]
        ),
        (
            &serde_json::json!(240),
            &serde_json::json!(0),
            &serde_json::json!("sgs")
        ),
        "{t}"
    );
    assert!(
        sgs_out.contains("(steps solved by the block-Jacobi PCG 0, the Gauss–Seidel PCG 240,"),
        "{sgs_out}"
    );
    assert_eq!(s["grid"][0], 11);
    // 121 vertices: below the size from which every core is used
    assert_eq!(s["threads"], 1);
    assert!(stdout.contains("1 thread\n"), "{stdout}");
    assert!((s["simulated_s"].as_f64().unwrap() - 0.2).abs() < 1e-9);
    // hanging in the air: no contacts
    assert_eq!(
        (&s["final_contacts"], &s["final_contacts_held"]),
        (&0.into(), &0.into())
    );
    let ply = std::fs::read_to_string(out.join("final.ply")).unwrap();
    assert!(ply.starts_with("ply\nformat ascii 1.0"));
    assert!(ply.contains("element vertex 121") && ply.contains("element face 200"));
    let csv = std::fs::read_to_string(out.join("energy.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert!(rows[0].starts_with("time_s,kinetic_J"));
    // 120 Hz rows (every 10 steps of 1/1200 s): t = 0 and 24 rows
    assert_eq!(rows.len(), 1 + 1 + 24);
    // the cloth, held by its corners, sags: it gains kinetic energy
    let last: Vec<f64> = rows
        .last()
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect();
    assert!(last[1] > 0.0);
}

/// The text of `free_fall.yaml` with its fabric's path made absolute, for a
/// variant written to `dir` (created).
fn free_fall_elsewhere(dir: &std::path::Path) -> String {
    std::fs::create_dir_all(dir).unwrap();
    let text = std::fs::read_to_string("config/scenes/free_fall.yaml").unwrap();
    let fabric = concat!(env!("CARGO_MANIFEST_DIR"), "/config/fabrics/");
    text.replace("../fabrics/", fabric)
}

/// `drape --hinges` and the scene's `cloth.hinges` choose the hinge layout
/// (the flag over the key); `summary.json` names it, and the pairs make a
/// different drape from the single hinges.
#[test]
fn drape_takes_the_hinge_layout_from_the_flag_and_the_scene_file() {
    let out = tmp("hinges");
    let text = free_fall_elsewhere(&out);
    let with_key = text.replacen("cloth:\n", "cloth:\n  hinges: mirror_symmetric\n", 1);
    assert_ne!(with_key, text, "free_fall.yaml has a cloth section");
    let (plain, keyed) = (out.join("plain.yaml"), out.join("keyed.yaml"));
    std::fs::write(&plain, &text).unwrap();
    std::fs::write(&keyed, &with_key).unwrap();
    let run = |scene: &std::path::Path, flag: Option<&str>, name: &str| {
        let dir = out.join(name);
        let mut cmd = support::garment_sim();
        cmd.arg("drape")
            .arg(scene)
            .args(["--duration", "0.1", "--out"])
            .arg(&dir);
        if let Some(f) = flag {
            cmd.args(["--hinges", f]);
        }
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap())
                .unwrap();
        let ply = std::fs::read_to_string(dir.join("final.ply")).unwrap();
        (s["hinges"].as_str().unwrap().to_string(), ply)
    };
    let (h_default, p_default) = run(&plain, None, "default");
    let (h_flag, p_flag) = run(&plain, Some("mirror_symmetric"), "flag");
    let (h_key, p_key) = run(&keyed, None, "key");
    let (h_over, p_over) = run(&keyed, Some("skewed"), "over");
    assert_eq!(
        [&h_default, &h_flag, &h_key, &h_over],
        ["skewed", "mirror_symmetric", "mirror_symmetric", "skewed"]
    );
    assert_eq!(p_flag, p_key, "the flag and the key make the same cloth");
    assert_eq!(p_default, p_over, "so do the default and --hinges skewed");
    assert_ne!(p_default, p_flag, "the pairs drape differently");
}

/// The scene's `cg_tolerance` sets the PCG's relative tolerance; `--cg-tolerance`
/// wins over it (Blender's own tolerance is 1e-2, docs/benchmarks.md).
#[test]
fn the_scene_file_sets_the_pcg_tolerance() {
    use garment_sim::scene::{Overrides, Scene};
    let out = tmp("cg_tolerance");
    let path = out.join("loose.yaml");
    std::fs::write(&path, free_fall_elsewhere(&out) + "cg_tolerance: 0.01\n").unwrap();
    let sc = Scene::load(&path).unwrap();
    let sim = sc.build(&Overrides::default()).unwrap();
    assert_eq!(sim.params().cg_tolerance, 0.01);
    let sim = sc
        .build(&Overrides {
            cg_tolerance: Some(1e-4),
            ..Default::default()
        })
        .unwrap();
    assert_eq!(sim.params().cg_tolerance, 1e-4);
    let plain = Scene::load(std::path::Path::new("config/scenes/free_fall.yaml")).unwrap();
    let sim = plain.build(&Overrides::default()).unwrap();
    assert_eq!(sim.params().cg_tolerance, 1e-6, "the default");
}

/// A trial's solver and PCG tolerance come from its file unless overridden
/// (`trial --solver`, `--cg-tolerance`; the node's `solver` and
/// `cg_tolerance` parameters pass the same overrides).
#[test]
fn a_trial_takes_the_solver_and_tolerance_overrides() {
    use garment_sim::solver::LinearSolverKind;
    use garment_sim::trial::{Overrides, Trial};
    let t = Trial::load(std::path::Path::new("config/trials/skirt_on_anny.yaml")).unwrap();
    let coarse = Overrides {
        spacing: Some(0.02),
        ..Default::default()
    };
    let (sim, _) = t.build(&coarse).unwrap();
    assert_eq!(
        sim.params().linear_solver,
        t.file.run.solver.unwrap_or_default()
    );
    assert_eq!(sim.params().cg_tolerance, 1e-6);
    let (sim, _) = t
        .build(&Overrides {
            solver: Some(LinearSolverKind::Amg),
            cg_tolerance: Some(1e-3),
            ..coarse
        })
        .unwrap();
    assert_eq!(sim.params().linear_solver, LinearSolverKind::Amg);
    assert_eq!(sim.params().cg_tolerance, 1e-3);
}

/// `drape` and `trial` take the same overrides (one type flattened into
/// both); the ones a command cannot honour are refused, naming the flag and
/// what to use instead, before anything runs; `--no-hysteresis` reaches a
/// trial's step as it does a drape's.
#[test]
fn a_flag_a_command_cannot_honour_is_refused_naming_it() {
    let out = tmp("refused");
    for (args, flag, instead) in [
        (
            &[
                "trial",
                "config/trials/skirt_on_anny.yaml",
                "--duration",
                "1",
            ][..],
            "--duration",
            "--max-time",
        ),
        (
            &[
                "trial",
                "config/trials/skirt_on_anny.yaml",
                "--hinges",
                "skewed",
            ][..],
            "--hinges",
            "garment file",
        ),
        (
            &["drape", "config/scenes/table_drape.yaml", "--max-time", "1"][..],
            "--max-time",
            "--duration",
        ),
    ] {
        let o = support::garment_sim()
            .args(args)
            .arg("--out")
            .arg(&*out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains(&format!("{flag}: not for a")) && err.contains(instead),
            "{args:?}: {err}"
        );
    }
    // a dressing's --max-time is checked before anything runs
    let o = support::garment_sim()
        .args([
            "trial",
            "config/trials/tshirt_dressing.yaml",
            "--max-time",
            "-1",
        ])
        .args(["--spacing", "0.03", "--out"])
        .arg(&*out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--max-time") && err.contains("-1"), "{err}");
    use garment_sim::trial::{Overrides, Trial};
    let t = Trial::load(std::path::Path::new("config/trials/skirt_on_anny.yaml")).unwrap();
    let ov = Overrides {
        spacing: Some(0.03),
        ..Default::default()
    };
    assert!(t.build(&ov).unwrap().0.params().hysteresis);
    let no = Overrides {
        hysteresis: Some(false),
        ..ov
    };
    assert!(!t.build(&no).unwrap().0.params().hysteresis);
}

#[test]
fn a_bad_scene_is_a_clear_error_not_a_panic() {
    let dir = tmp("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("s.yaml");
    std::fs::write(
        &p,
        "cloth: { fabric: x.yaml, size: [1, 1], spacing: 0.1 }\ndt: 0.001\n",
    )
    .unwrap();
    let o = support::garment_sim()
        .args(["drape"])
        .arg(&p)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("s.yaml") && err.contains("duration"), "{err}");
    assert!(!err.contains("panicked"));
}

/// The node refuses bad start-up input before it joins the DDS domain, and
/// says which parameter, file or line is wrong.
#[test]
fn node_start_up_errors_name_what_is_wrong() {
    let dir = tmp("node_args");
    std::fs::create_dir_all(&dir).unwrap();
    let bad_yaml = dir.join("bad.yaml");
    std::fs::write(
        &bad_yaml,
        "/**:\n  ros__parameters:\n    publish_rate: [1, 2\n",
    )
    .unwrap();
    let wrong_type = dir.join("wrong.yaml");
    std::fs::write(
        &wrong_type,
        "garment_sim:\n  ros__parameters:\n    paused: 3\n",
    )
    .unwrap();
    let missing_scene = dir.join("nowhere.yaml");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["-p".into(), "bogus:=1".into()],
            "unknown parameter \"bogus\"",
        ),
        (
            vec!["-p".into(), "publish_rate:=-3".into()],
            "publish_rate = -3",
        ),
        (vec!["-p".into(), "solver:=lu".into()], "solver = \"lu\""),
        (vec!["-p".into(), "threads:=-1".into()], "threads = -1"),
        (vec!["-p".into(), "threads:=65".into()], "threads = 65"),
        (vec!["-r".into(), "__ns:=/1bad".into()], "namespace"),
        (vec!["-x".into()], "unknown argument \"-x\""),
        (
            vec!["--params-file".into(), bad_yaml.display().to_string()],
            "not valid YAML",
        ),
        (
            vec!["--params-file".into(), wrong_type.display().to_string()],
            "paused",
        ),
        (
            vec!["-p".into(), format!("scene:={}", missing_scene.display())],
            "nowhere.yaml",
        ),
    ];
    for (args, expect) in cases {
        let o = support::garment_sim()
            .arg("node")
            .arg("--ros-args")
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(err.contains(expect), "{args:?}: {err}");
    }
    // and `drape` refuses a thread count beyond the limit, naming it
    let o = support::garment_sim()
        .args(["drape", "config/scenes/free_fall.yaml", "--threads", "65"])
        .arg("--out")
        .arg(dir.join("threads"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("threads = 65: at most 64"),
        "{err}"
    );
}

/// `bench --repeat N` times the same steps N times (each run from the scene
/// built and warmed up again), not N successive stretches of the drape: the
/// median run is then like the others, and the mean iterations are those of
/// one run. (Before, the runs followed one another, and the median and the
/// iterations came from later, calmer stretches: 17.8 iterations a step at
/// `--repeat 3` against 9.0 at `--repeat 1` on this grid.)
#[test]
fn bench_repeats_measure_the_same_steps() {
    let iters = |repeat: &str| -> f64 {
        let stdout = bench_5cm("0.001", "pcg", repeat);
        let row = bench_rows(&stdout).into_iter().next().expect("a row");
        // columns: spacing, grid, dt, solver, ms/step, assembly, solve,
        // contacts, RTF, iters, …
        row[9].parse().unwrap_or_else(|_| panic!("{row:?}"))
    };
    let (one, three) = (iters("1"), iters("3"));
    assert!(one > 0.0, "{one}");
    assert_eq!(
        one, three,
        "--repeat 1: {one} iterations a step, --repeat 3: {three}"
    );
}

/// `bench` on the 5 cm table drape, 20 steps a run after 0.01 s: its output.
fn bench_5cm(dt: &str, solver: &str, repeat: &str) -> String {
    let o = support::garment_sim()
        .args([
            "bench",
            "--spacing",
            "0.05",
            "--dt",
            dt,
            "--solver",
            solver,
            "--steps",
            "20",
            "--repeat",
            repeat,
            "--warmup",
            "0.01",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{stdout}");
    stdout
}

/// The rows of `bench`'s output on the 5 cm grid, split into columns.
fn bench_rows(stdout: &str) -> Vec<Vec<&str>> {
    stdout
        .lines()
        .filter(|l| l.trim_start().starts_with("0.05"))
        .map(|l| l.split_whitespace().collect())
        .collect()
}

/// `bench` prints one row per case with the time per step, its split into
/// assembly, solve and contacts (which add up to at most the whole), the
/// real-time factor (dt / time per step), the peak memory and the window of
/// simulated time measured.
#[test]
fn bench_reports_time_per_step_and_its_phases() {
    let stdout = bench_5cm("0.001,0.0001", "pcg,cholesky", "3");
    let header = stdout
        .lines()
        .find(|l| l.contains("ms/step"))
        .expect("header");
    for col in [
        "assembly",
        "solve",
        "contacts",
        "RTF",
        "iters",
        "peak RSS MB",
        "threads",
        "window s",
    ] {
        assert!(header.contains(col), "header lacks {col}: {header}");
    }
    let rows = bench_rows(&stdout);
    assert_eq!(rows.len(), 4, "{stdout}");
    for r in &rows {
        let num = |k: usize| -> f64 { r[k].parse().unwrap_or_else(|_| panic!("{r:?}")) };
        assert_eq!(r[1], "11x11");
        let (dt, ms, asm, solve, contacts, rtf) = (num(2), num(4), num(5), num(6), num(7), num(8));
        assert!(asm > 0.0 && solve > 0.0 && contacts >= 0.0, "{r:?}");
        // the phases are parts of the step (each printed to 0.001 ms)
        assert!(asm + solve + contacts <= ms * 1.01 + 0.003, "{r:?}");
        // ms/step is printed to 0.001 ms
        assert!(
            (rtf - dt * 1e3 / ms).abs() <= rtf * (0.0005 / ms + 0.002) + 0.002,
            "{r:?}"
        );
        assert!(num(9) >= 1.0 && num(10) > 1.0, "{r:?}");
        // 121 vertices: one thread (every core from 500)
        assert_eq!(r[11], "1", "{r:?}");
        // the simulated times measured: after the warm-up of 0.01 s, at most
        // 3 × 20 steps (at 1e-4 s: 60 steps, 0.006 s), then 20 steps
        let (t0, t1) = r[12].split_once('-').unwrap_or_else(|| panic!("{r:?}"));
        let (t0, t1): (f64, f64) = (t0.parse().unwrap(), t1.parse().unwrap());
        let start = (0.01 / dt).round().min(60.0) * dt;
        assert!(
            (t0 - start).abs() < 1e-9 && (t1 - start - 20.0 * dt).abs() < 1e-9,
            "{r:?}"
        );
    }
}
