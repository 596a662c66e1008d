//! `tumble run`'s chain (calibrate → allan → audit → vio) on simulated
//! recordings: every stage runs and feeds the next, the report links only
//! figures that exist, skipped stages reuse an earlier run's files (never stale
//! ones), and bad arguments give clear errors.

use std::path::{Path, PathBuf};
use std::process::Command;
use tumble::pipeline::{run_chain, ChainInputs, ChainOptions, Stage, Status};
use tumble::sim::{hide_effect, simulate, Scenario, SimConfig};
use tumble::vio::{VioInput, VioOptions};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tumble_pipeline_{name}_{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    d
}

/// Every `![..](path)` of the report, checked to exist relative to `out`.
fn linked_figures(out: &Path) -> Vec<String> {
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let links: Vec<String> = md.split("](").skip(1).map(|s| s.split(')').next().unwrap().to_string()).collect();
    let figures: Vec<String> = links.into_iter().filter(|l| l.ends_with(".png")).collect();
    for f in &figures {
        assert!(out.join(f).is_file(), "report.md links {f}, which does not exist");
    }
    figures
}

fn status(r: &tumble::pipeline::ChainReport, s: Stage) -> &Status {
    &r.stages.iter().find(|x| x.stage == s).unwrap().status
}

#[test]
fn chain_runs_every_stage_and_reuses_files_when_skipped() {
    let mut cfg = SimConfig::default();
    hide_effect(&mut cfg, "g_sensitivity", 2.0).unwrap();
    let tumble = simulate(Scenario::Tumble, &cfg, 3).unwrap();
    let still = simulate(Scenario::Static, &SimConfig { duration_s: Some(1200.0), ..cfg.clone() }, 3).unwrap();
    // 40 s: the simulator's shortest walks (25 s) squeeze the loop into fast
    // turns the estimator does not survive with any calibration (see the VIO notes).
    let wcfg = SimConfig { duration_s: Some(40.0), ..cfg.clone() };
    let walk = std::sync::Arc::new(simulate(Scenario::Walk, &wcfg, 3).unwrap());
    let out = temp_dir("full");
    let opts = ChainOptions {
        calib: tumble::calib::CalibOptions { gravity: cfg.gravity, ..Default::default() },
        vio: VioOptions::for_simulation(&wcfg),
        ..Default::default()
    };

    // Full chain: the VIO gets the audited calibration (with the effect).
    let walk1 = walk.clone();
    let seen: std::sync::Arc<std::sync::Mutex<Vec<String>>> = Default::default();
    let seen1 = seen.clone();
    let inputs = ChainInputs {
        tumble: Some(tumble.imu.to_recording()),
        still: Some(still.imu.to_recording()),
        vio: Some(Box::new(move |cal| {
            seen1.lock().unwrap().extend(cal.map(|c| c.effect_ids()).unwrap_or_default());
            Ok(VioInput::from_simulation_calibrated(&walk1, cal)?)
        })),
        ..Default::default()
    };
    let mut started = Vec::new();
    let r = run_chain(inputs, &opts, &out, &mut |p| {
        if let tumble::pipeline::Progress::Stage(s, _) = p {
            started.push(s)
        }
    })
    .unwrap();
    assert_eq!(started, Stage::ALL.to_vec());
    for s in Stage::ALL {
        assert!(matches!(status(&r, s), Status::Ran(_)), "{s:?}: {:?}", status(&r, s));
    }
    assert_eq!(
        *seen.lock().unwrap(),
        vec!["gyro_g_sensitivity".to_string()],
        "the VIO must get the audited calibration"
    );
    let (_, _, summary) = r.vio.as_ref().unwrap();
    assert!(summary.resets == 0 && summary.ate_rmse_m.unwrap() < 0.3, "{}", summary.table());
    let figs = linked_figures(&out);
    for f in
        ["calibrate/static_detection.png", "allan/allan_gyro.png", "audit/audit_gap.png", "vio/eval/trajectory_top.png"]
    {
        assert!(figs.iter().any(|x| x == f), "{f} not in the report: {figs:?}");
    }
    for f in ["calibrate/calibration.json", "allan/imu.yaml", "audit/calibration.json", "vio/trajectory.txt"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let summary_text = r.summary();
    assert!(summary_text.contains("gyro_g_sensitivity") && summary_text.contains("report.md"), "{summary_text}");

    // Only the VIO again: the other stages come from the files just written.
    let walk2 = walk.clone();
    let seen2 = seen.clone();
    seen.lock().unwrap().clear();
    let inputs = ChainInputs {
        vio: Some(Box::new(move |cal| {
            seen2.lock().unwrap().extend(cal.map(|c| c.effect_ids()).unwrap_or_default());
            Ok(VioInput::from_simulation_calibrated(&walk2, cal)?)
        })),
        ..Default::default()
    };
    let first_trajectory = std::fs::read(out.join("vio/trajectory.txt")).unwrap();
    let skip = ChainOptions { skip: vec![Stage::Calibrate, Stage::Allan, Stage::Audit], ..opts.clone() };
    let r2 = run_chain(inputs, &skip, &out, &mut |_| {}).unwrap();
    // The calibration and noise read back from the files are exactly those held
    // in memory the first time: the VIO gives the same trajectory, byte for byte.
    assert!(std::fs::read(out.join("vio/trajectory.txt")).unwrap() == first_trajectory);
    let audit_file = out.join("audit/calibration.json").display().to_string();
    assert_eq!(*status(&r2, Stage::Audit), Status::Reused(audit_file));
    assert!(matches!(status(&r2, Stage::Allan), Status::Reused(f) if f.ends_with("imu.yaml")));
    assert_eq!(*seen.lock().unwrap(), vec!["gyro_g_sensitivity".to_string()]);
    assert_eq!(r2.noise, Some(tumble::io::ImuNoise::read(&out.join("allan/imu.yaml")).unwrap()));
    // The reused stages' figures are still in the report.
    assert!(linked_figures(&out).iter().any(|f| f == "audit/audit_gap.png"));

    // Calibrate again but skip the audit: the earlier audit is stale and must not be used.
    let inputs = ChainInputs { tumble: Some(tumble.imu.to_recording()), ..Default::default() };
    let stale = ChainOptions { skip: vec![Stage::Audit], ..opts.clone() };
    let r3 = run_chain(inputs, &stale, &out, &mut |_| {}).unwrap();
    assert!(matches!(status(&r3, Stage::Calibrate), Status::Ran(_)));
    assert_eq!(*status(&r3, Stage::Audit), Status::Skipped("skipped".into()));
    assert!(r3.final_calibration.as_ref().unwrap().effect_ids().is_empty());
    assert_eq!(*status(&r3, Stage::Vio), Status::Skipped("no VIO data given".into()));
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn chain_without_inputs_skips_with_reasons() {
    let out = temp_dir("empty");
    let r = run_chain(ChainInputs::default(), &ChainOptions::default(), &out, &mut |_| {}).unwrap();
    for s in Stage::ALL {
        assert!(matches!(status(&r, s), Status::Skipped(_)), "{s:?}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("no tumble recording") && md.contains("no VIO data given"), "{md}");
    // A stage's error stops the chain and names the stage.
    let still = simulate(Scenario::Static, &SimConfig { duration_s: Some(120.0), ..Default::default() }, 1).unwrap();
    let inputs = ChainInputs { tumble: Some(still.imu.to_recording()), ..Default::default() };
    let e = run_chain(inputs, &ChainOptions::default(), &out, &mut |_| {}).err().unwrap().to_string();
    assert!(e.starts_with("calibrate:") && e.contains("static intervals"), "{e}");
    assert!("alan".parse::<Stage>().unwrap_err().to_string().contains("calibrate, allan, audit, vio"));
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn run_command_refuses_bad_arguments() {
    let out = temp_dir("cli");
    let run = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_tumble")).arg("run").args(args).output().unwrap();
        assert!(!o.status.success(), "{args:?} should fail");
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    let o = out.to_str().unwrap();
    assert!(run(&["--out", o]).contains("nothing to do"));
    assert!(run(&["--out", o, "--tumble", "x", "--skip", "calibrate,foo"]).contains("unknown stage `foo`"));
    let e = run(&["--out", o, "--tumble", "/nonexistent/tumble.csv"]);
    assert!(e.contains("/nonexistent/tumble.csv"), "{e}");
    let e = run(&["--out", o, "--vio", "x", "--noise", "/nonexistent/imu.yaml"]);
    assert!(e.contains("/nonexistent/imu.yaml"), "{e}");
    if !cfg!(feature = "rerun") {
        // Refused before any stage runs, with the way to get it.
        let e = run(&["--out", o, "--vio", "x", "--rerun", "r.rrd"]);
        assert!(e.contains("--features rerun") && e.contains("r.rrd"), "{e}");
        let vio = Command::new(env!("CARGO_BIN_EXE_tumble"))
            .args(["vio", "x", "--out", o, "--rerun", "r.rrd"])
            .output()
            .unwrap();
        assert!(String::from_utf8_lossy(&vio.stderr).contains("--features rerun"));
    }
    // A motion the simulator refuses is reported as the simulation's, not the folder's, fault.
    let sim = Command::new(env!("CARGO_BIN_EXE_tumble"))
        .args(["sim", "walk", "--duration", "20", "--out", o])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&sim.stderr).to_string();
    assert!(!sim.status.success() && e.contains("simulation: a 20 s walk") && !e.contains(o), "{e}");
    // Plot options refuse what they cannot draw.
    let bal = Command::new(env!("CARGO_BIN_EXE_tumble"))
        .args(["solve", "no_such_problem.txt", "--plot", "x.png"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&bal.stderr).contains("--plot draws pose graphs"));
    std::fs::remove_dir_all(&out).ok();
}
