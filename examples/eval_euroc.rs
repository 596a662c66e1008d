//! Evaluate the estimator on every real EuRoC recording the project has and
//! print one table: each whole sequence under `euroc/full_imu/` (real IMU,
//! a simulated stereo camera along the ground truth, EuRoC's two cameras 0.11 m
//! apart) and V1_01 with EqVIO's real
//! feature tracks (first 30 s), against EuRoC's ground truth with biases; and
//! `imu_april` (72 s of real IMU in front of an AprilGrid, its real corners as
//! features, EuRoC's calibration of the cameras) against a per-frame PnP of
//! the corners with that calibration (no biases to compare; aligned in 6 DOF,
//! as the target's tilt against gravity is known only to the accelerometer's bias).
//!
//! `cargo run --release --example eval_euroc -- [--noise-from-static] [--zoh] [--fixed-noise] [--inverse-depth-only] [--mono] [--seed N]
//! [--noise-in-flight] [--walk-scale G[,A]] [--online on|auto] [--blackout FROM,SECONDS] [--from SECONDS] [--only TEXT] [--out DIR]
//! [--keyframe-parallax PX] [--keyframe-min-interval S] [--markdown]`
//!
//! `--only` runs the cases whose name contains TEXT; `--out` writes each
//! case's files and figures (as `tumble vio` does) into `DIR/<case>/`;
//! `--keyframe-parallax` and `--keyframe-min-interval` replace the keyframe
//! policy's parallax threshold and shortest interval (as `tumble vio`'s
//! flags of those names) in every case.
//!
//! Columns: ATE (position + yaw aligned), RPE over ~10 % of the path (mean
//! translation error in % of the distance, rotation in degrees), rotation
//! RMSE, bias RMSE (gyro, accel) and its ratio to the floor `√(N·K)` the noise
//! in use predicts, the bias NEES per axis (error²/σ², 1 = consistent), the
//! IMU white noise in use at the end, resets (and the pieces, when a start
//! was withdrawn: each piece is aligned by itself) and speed. The flags switch the
//! estimator's choices off or on, to compare: `--noise-from-static` raises the
//! noise to the static start's spread, `--zoh` integrates with the zero-order
//! hold instead of the midpoint rule, `--fixed-noise` does not measure the
//! noise in motion, `--inverse-depth-only` fixes each landmark's bearing at
//! its anchor pixel (VINS-Mono's landmarks), `--mono` simulates cam0
//! alone, `--walk-scale G,A` multiplies the bias random walks given
//! (gyro, accelerometer; `docs/vio.md`, "The bias random walk in flight"),
//! `--noise-in-flight` gives each case the noise its IMU shows in flight on
//! the *other* sequences under `full_imu/` (`tumble allan --groundtruth` on
//! each, pooled: [`ImuNoise::pooled`]; V1_01, which is not among them, gets
//! all of them; imu_april, moved by hand with the rotors off, keeps the
//! datasheet's) instead of the datasheet's,
//! `--online auto` estimates imu_april's camera calibration online in the
//! `auto` mode instead of `on` (freed once the motion determines it), and
//! `--blackout FROM,SECONDS` removes every feature over that span of each
//! case and says, per case, what was reported and how the estimate fares
//! from 2 s after the features return (aligned by itself). `--from SECONDS`
//! cuts every recording before that time, so that each starts in motion
//! wherever it is then (the start's warnings are printed).

use std::path::{Path, PathBuf};
use tumble::eval::{Alignment, EvalOptions};
use tumble::io::ImuNoise;
use tumble::vio::VioSource;
use tumble::vio::{piece_starts_s, run, summarize, trajectory, Summary, VioInput, VioOptions};

/// The command line.
struct Args {
    flags: Vec<String>,
    seed: u64,
    only: Option<String>,
    out: Option<PathBuf>,
    walk_scale: [f64; 2],
    cuts: Cuts,
    online: tumble::vio::Estimate,
    /// `--keyframe-parallax` \[px\].
    keyframe_parallax_px: Option<f64>,
    /// `--keyframe-min-interval` \[s\].
    keyframe_min_interval_s: Option<f64>,
}

impl Args {
    fn has(&self, f: &str) -> bool {
        self.flags.iter().any(|a| a == f)
    }

    fn parse() -> Result<Args, String> {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let value = |f: &str| args.iter().position(|a| a == f).and_then(|i| args.get(i + 1)).cloned();
        const FLAGS: [&str; 7] = [
            "--mono",
            "--noise-from-static",
            "--noise-in-flight",
            "--zoh",
            "--fixed-noise",
            "--inverse-depth-only",
            "--markdown",
        ];
        const VALUED: [&str; 9] = [
            "--seed",
            "--only",
            "--out",
            "--walk-scale",
            "--online",
            "--blackout",
            "--from",
            "--keyframe-parallax",
            "--keyframe-min-interval",
        ];
        let known = |i: usize, a: &str| {
            FLAGS.contains(&a) || VALUED.contains(&a) || (i > 0 && VALUED.contains(&args[i - 1].as_str()))
        };
        if let Some((_, bad)) = args.iter().enumerate().find(|(i, a)| !known(*i, a)) {
            return Err(format!("unknown argument {bad}; see the example's doc comment"));
        }
        let walk_scale = value("--walk-scale").map(|v| parse_walk_scale(&v)).transpose();
        let walk_scale = walk_scale.map_err(|e| format!("--walk-scale: {e}"))?.unwrap_or([1.0, 1.0]);
        let blackout =
            value("--blackout").map(|v| parse_blackout(&v)).transpose().map_err(|e| format!("--blackout: {e}"))?;
        let from = match value("--from").map(|v| v.parse::<f64>()).transpose() {
            Ok(f) if f.is_none_or(|f| f.is_finite() && f >= 0.0) => f,
            _ => return Err("--from: expected a time in seconds (≥ 0)".into()),
        };
        let number = |f: &str| value(f).map(|v| v.parse::<f64>().map_err(|_| format!("{f}: `{v}` is not a number")));
        let keyframe_parallax_px = number("--keyframe-parallax").transpose()?;
        let keyframe_min_interval_s = number("--keyframe-min-interval").transpose()?;
        let online = match value("--online").as_deref() {
            None | Some("on") => tumble::vio::Estimate::On,
            Some("auto") => tumble::vio::Estimate::Auto,
            Some(v) => return Err(format!("--online: `{v}` is neither on nor auto")),
        };
        Ok(Args {
            seed: value("--seed").and_then(|v| v.parse().ok()).unwrap_or(1),
            only: value("--only"),
            out: value("--out").map(PathBuf::from),
            walk_scale,
            cuts: Cuts { blackout, from },
            online,
            keyframe_parallax_px,
            keyframe_min_interval_s,
            flags: args,
        })
    }
}

fn main() {
    let args = match Args::parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let Some(data) = tumble::io::datasets::dataset("euroc") else {
        return;
    };
    let mut opts = VioOptions::default();
    opts.noise.from_static = args.has("--noise-from-static");
    opts.noise.measure_in_motion = !args.has("--fixed-noise");
    opts.window.landmark_bearings = !args.has("--inverse-depth-only");
    if let Some(px) = args.keyframe_parallax_px {
        opts.window.keyframe_parallax_px = px;
    }
    if let Some(s) = args.keyframe_min_interval_s {
        opts.window.keyframe_min_interval_s = s;
    }
    if args.has("--zoh") {
        opts.noise.imu.scheme = tumble_factors::imu_preint::Scheme::ZeroOrderHold;
    }
    let mut seqs: Vec<PathBuf> = std::fs::read_dir(data.join("full_imu"))
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.join("mav0").is_dir()).collect())
        .unwrap_or_default();
    seqs.sort();
    let flight: Vec<(PathBuf, ImuNoise)> = if args.has("--noise-in-flight") {
        match seqs.iter().map(|s| noise_in_flight(s, opts.noise.gravity).map(|n| (s.clone(), n))).collect() {
            Ok(f) => f,
            Err(e) => {
                eprintln!("--noise-in-flight: {e}");
                std::process::exit(1);
            }
        }
    } else {
        Vec::new()
    };
    let cases = cases(&args, &data, seqs, &opts);
    if cases.is_empty() {
        println!("SKIPPED: no EuRoC data under {}", data.display());
        return;
    }
    let (rows, notes) = run_cases(&args, &cases, &flight, &data);
    print_table(&rows, args.has("--markdown"));
    for n in notes {
        println!("{n}");
    }
}

/// The distance between EuRoC's cam0 and cam1 \[m\] (their `sensor.yaml`s: 0.1101).
const EUROC_BASELINE_M: f64 = 0.11;

/// Every case: each whole sequence with a simulated camera, V1_01 with
/// EqVIO's tracks, imu_april against its PnP truth (and with its camera
/// estimated online from EuRoC's calibration and from a wrong one).
fn cases(args: &Args, data: &Path, seqs: Vec<PathBuf>, opts: &VioOptions) -> Vec<(String, Case, VioOptions)> {
    let mut cases: Vec<(String, Case, VioOptions)> = Vec::new();
    for s in seqs {
        let name = format!("{} (sim. camera)", s.file_name().unwrap_or_default().to_string_lossy());
        let baseline = if args.has("--mono") { 0.0 } else { EUROC_BASELINE_M };
        let source = VioSource {
            simulate_camera: Some(args.seed),
            simulated_stereo_baseline_m: Some(baseline),
            ..Default::default()
        };
        cases.push((name, Case::Source(s, Box::new(source)), opts.clone()));
    }
    let eqvio = data.join("eqvio_V1_01_30s.csv");
    if eqvio.is_file() {
        let source = VioSource { groundtruth: Some(data.join("groundtruth/V1_01_easy.csv")), ..Default::default() };
        // EqVIO's tuned pixel noise for this file (σ² = 3.72 px²).
        let mut o = opts.clone();
        o.noise.pixel_sigma = 1.93;
        cases.push(("V1_01 30 s (EqVIO tracks)".into(), Case::Source(eqvio, Box::new(source)), o));
    }
    let april = data.join("imu_april");
    if april.join("target.yaml").is_file() {
        let name = "imu_april 72 s (target corners; PnP truth)";
        cases.push((name.into(), Case::Target(april.clone(), None), opts.clone()));
        // T_BC and the time offset estimated online: from EuRoC's values, and from
        // EuRoC's T_BC turned by 2° and moved by 3 cm with the stamps 8 ms late.
        let mut o = opts.clone();
        o.camera.extrinsics = args.online;
        o.camera.time_offset = args.online;
        let name = "imu_april, T_BC and time offset estimated online";
        cases.push((name.into(), Case::Target(april.clone(), Some(0.0)), o.clone()));
        let name = "imu_april, T_BC 2°/3 cm and stamps 8 ms off, estimated online";
        cases.push((name.into(), Case::Target(april, Some(1.0)), o));
    }
    cases
}

/// Run the cases `--only` selects: a table row per case and the notes.
fn run_cases(
    args: &Args,
    cases: &[(String, Case, VioOptions)],
    flight: &[(PathBuf, ImuNoise)],
    data: &Path,
) -> (Vec<(String, Summary)>, Vec<String>) {
    let mut rows = Vec::new();
    let mut notes = Vec::new();
    for (name, case, o) in cases {
        if args.only.as_ref().is_some_and(|t| !name.contains(t.as_str())) {
            continue;
        }
        eprintln!("running {name} …");
        let dir = args.out.as_ref().map(|d| d.join(folder_name(name)));
        // The flights' noise for a flight (every sequence's but the case's own);
        // imu_april is moved by hand, rotors off, and keeps its own figures.
        let noise = match case {
            Case::Source(path, _) => {
                let others: Vec<ImuNoise> = flight.iter().filter(|(p, _)| p != path).map(|(_, n)| *n).collect();
                ImuNoise::pooled(&others)
            }
            Case::Target(..) => None,
        };
        match evaluate(case, o, noise, args.walk_scale, &args.cuts, data, dir.as_deref()) {
            Ok(Some((s, note))) => {
                notes.extend(note.map(|n| format!("{name}: {n}")));
                rows.push((name.clone(), s));
            }
            Ok(None) => {
                notes.push(format!("{name}: ends before {} s (--from): not run", args.cuts.from.unwrap_or(0.0)))
            }
            Err(e) => {
                eprintln!("{name}: {e}");
                std::process::exit(1);
            }
        }
    }
    (rows, notes)
}

/// The noise the IMU of the ASL sequence `dir` shows in flight against its
/// ground truth (`gravity` \[m/s²\]): the Allan analysis of its error in
/// motion, each axis's own figures (`tumble allan --groundtruth`).
fn noise_in_flight(dir: &Path, gravity: f64) -> Result<ImuNoise, String> {
    let ds = tumble::io::asl::read_asl(dir, &Default::default()).map_err(|e| e.to_string())?;
    let truth = ds.groundtruth.as_ref().ok_or_else(|| format!("{}: no ground truth", dir.display()))?;
    let (noise, span) =
        tumble::allan::in_motion::noise_in_motion(&ds.imu, truth, gravity).map_err(|e| e.to_string())?;
    let a = noise.axes.ok_or("no per-axis noise")?;
    let xyz = |v: [f64; 3]| format!("{:.1e} {:.1e} {:.1e}", v[0], v[1], v[2]);
    eprintln!(
        "  {} in flight ({:.0}–{:.0} s): gyro white {}, walk {}; accel white {}, walk {}",
        dir.file_name().unwrap_or_default().to_string_lossy(),
        span.from_s,
        span.to_s,
        xyz(a.gyroscope_noise_density),
        xyz(a.gyroscope_random_walk),
        xyz(a.accelerometer_noise_density),
        xyz(a.accelerometer_random_walk),
    );
    Ok(noise)
}

/// `G` or `G,A`: the factors on the gyro's and the accelerometer's bias
/// random walks (one factor for both when A is left out); positive and finite.
fn parse_walk_scale(v: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = v.split(',').collect();
    let num = |s: &str| -> Result<f64, String> {
        let x: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number (expected G or G,A)"))?;
        if x.is_finite() && x > 0.0 {
            Ok(x)
        } else {
            Err(format!("`{s}` must be positive and finite"))
        }
    };
    match parts.as_slice() {
        [g] => Ok([num(g)?, num(g)?]),
        [g, a] => Ok([num(g)?, num(a)?]),
        _ => Err(format!("`{v}`: expected G or G,A")),
    }
}

/// `FROM,SECONDS`: the blackout's start and length \[s\], finite, the length positive.
fn parse_blackout(v: &str) -> Result<[f64; 2], String> {
    let parts: Vec<f64> = v
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{v}`: expected FROM,SECONDS (numbers)"))?;
    match parts[..] {
        [from, len] if from.is_finite() && len.is_finite() && len > 0.0 => Ok([from, len]),
        _ => Err(format!("`{v}`: expected FROM,SECONDS with a finite start and a positive length")),
    }
}

/// `p` with its bias random walks (and their per-axis figures) multiplied by `[gyro, accel]`.
fn scale_walks(p: &mut tumble_factors::imu_preint::PreintegrationParams, [g, a]: [f64; 2]) {
    p.gyro_random_walk *= g;
    p.accel_random_walk *= a;
    if let Some(axes) = p.axes.as_mut() {
        axes.gyro_random_walk.iter_mut().for_each(|d| *d *= g);
        axes.accel_random_walk.iter_mut().for_each(|d| *d *= a);
    }
}

/// What is taken out of every case's recording.
struct Cuts {
    /// Every feature over `[from, from + seconds]` (`--blackout`).
    blackout: Option<[f64; 2]>,
    /// Everything before this time \[s\] (`--from`).
    from: Option<f64>,
}

/// What a row of the table runs on.
enum Case {
    /// An input `tumble vio` opens (a path and how).
    Source(PathBuf, Box<VioSource>),
    /// A recording in front of a target (its folder), and whether its camera
    /// calibration is estimated online, from EuRoC's made wrong by this
    /// multiple of [`CAMERA_ERROR`].
    Target(PathBuf, Option<f64>),
}

/// The camera error of [`Case::Target`]'s perturbed run: 2° about an oblique
/// axis, 3 cm along the camera's x, stamps 8 ms late.
const CAMERA_ERROR: ([f64; 3], [f64; 3], f64) = ([1.0, -1.0, 1.0], [0.03, 0.0, 0.0], 0.008);

/// Where the perturbed run's trajectory is evaluated again \[s after its
/// first estimate\].
const LATE_S: f64 = 15.0;

/// A case's folder under `--out`: its name in lower case, each run of other
/// characters than letters and digits one `_` (`imu_april, T_BC 2°…` →
/// `imu_april_t_bc_2_…`), so that no two cases share one.
fn folder_name(name: &str) -> String {
    let mut s = String::new();
    for c in name.chars() {
        if c.is_ascii_alphanumeric() {
            s.push(c.to_ascii_lowercase());
        } else if !s.ends_with('_') {
            s.push('_');
        }
    }
    s.trim_matches('_').to_string()
}

/// Run one case as `tumble vio` does and summarize it against its ground
/// truth; with an online camera calibration, also a line on how far it
/// landed from EuRoC's. None when `--from` leaves nothing of it.
fn evaluate(
    case: &Case,
    opts: &VioOptions,
    noise: Option<ImuNoise>,
    walk_scale: [f64; 2],
    cuts: &Cuts,
    data: &Path,
    out: Option<&Path>,
) -> Result<Option<(Summary, Option<String>)>, String> {
    let mut opts = opts.clone();
    let mut correct = None;
    let mut input = match case {
        Case::Source(path, source) => VioInput::open(path, source, &mut |_, _| {}).map_err(|e| e.to_string())?.input,
        Case::Target(dir, perturbed) => {
            let cameras = data.join("V1_01_easy_micro");
            let (input, truth) =
                VioInput::from_target_recording(dir, &dir.join("target.yaml"), &cameras).map_err(|e| e.to_string())?;
            eprintln!(
                "  PnP ground truth: {} of {} frames with corners, median RMS {:.2} px",
                truth.posed, truth.frames, truth.median_rms_px
            );
            if let Some(k) = perturbed {
                let (axis, t, shift) = CAMERA_ERROR;
                let axis = nalgebra::Vector3::from(axis).normalize() * 2f64.to_radians() * *k;
                let shift = shift * k;
                let (input, c) = input.with_camera_error(axis, nalgebra::Vector3::from(t) * *k, shift);
                correct = Some((c, shift));
                input
            } else {
                input
            }
        }
    };
    if let Some(from) = cuts.from {
        input.drop_before(from);
        if input.frames.len() < 2 || input.imu.t.len() < 2 {
            return Ok(None);
        }
    }
    let blackout = cuts.blackout;
    if let Some([from, len]) = blackout {
        for f in input.frames.iter_mut().filter(|f| f.t > from && f.t < from + len) {
            f.features.clear();
        }
    }
    input.apply_noise(noise, &mut opts.noise.imu);
    scale_walks(&mut opts.noise.imu, walk_scale);
    let result = run(&input, &opts, None).map_err(|e| e.to_string())?;
    let mut summary = summarize(&input, &opts, &result, 10.0);
    // The target frame's tilt against gravity is known only through the
    // mean specific force, which an accelerometer bias of 0.1 m/s² tilts
    // by 0.6°: align in 6 DOF instead of position + yaw.
    let se3 = |result: &tumble::vio::VioResult| {
        let gt = input.groundtruth.as_ref().ok_or("no PnP ground truth")?;
        let eval_opts = EvalOptions {
            alignment: Alignment::Se3,
            piece_starts_s: piece_starts_s(&input, result),
            ..EvalOptions::default()
        };
        tumble::eval::evaluate(&trajectory(&input, result), None, gt, &eval_opts).map_err(|e| e.to_string())
    };
    if let (Case::Target(..), Some(_)) = (case, &input.groundtruth) {
        let ev = se3(&result)?;
        summary.ate_rmse_m = Some(ev.metrics.ate_rmse_m);
        summary.evaluation = Some(ev);
    }
    if let Some(dir) = out {
        tumble::vio::write_outputs(dir, &input, &result, &summary).map_err(|e| e.to_string())?;
    }
    let alignment = match case {
        Case::Target(..) => Alignment::Se3,
        Case::Source(..) => EvalOptions::default().alignment,
    };
    let blackout_note = blackout.map(|[from, len]| {
        let after = from + len + 2.0;
        let mut late = result.clone();
        late.estimates.retain(|e| e.t > after);
        let eval_opts =
            EvalOptions { alignment, piece_starts_s: piece_starts_s(&input, &late), ..EvalOptions::default() };
        let ev = input
            .groundtruth
            .as_ref()
            .map(|gt| tumble::eval::evaluate(&trajectory(&input, &late), None, gt, &eval_opts));
        let spans: Vec<String> = result.blind_spans.iter().map(|[a, b]| format!("{a:.2}–{b:.2} s")).collect();
        format!(
            "blackout {from}–{} s: blind spans reported {}, resets {}; from {after} s (aligned by itself): {}",
            from + len,
            if spans.is_empty() { "none".into() } else { spans.join(", ") },
            result.resets,
            match ev {
                Some(Ok(ev)) => format!(
                    "ATE {:.3} m, rotation RMSE {:.2}° ({:.2}° with the orientations aligned)",
                    ev.metrics.ate_rmse_m, ev.metrics.rotation_rmse_deg, ev.metrics.rotation_rmse_oriented_deg
                ),
                Some(Err(e)) => format!("not evaluated ({e})"),
                None => "no ground truth".into(),
            }
        )
    });
    let note = correct.zip(result.camera.as_ref()).map(|((c, shift), est)| {
        let (dr, dt) = est.difference(&c);
        // The first seconds are flown with the wrong calibration (held until
        // a window's length of keyframes is in the prior): the ATE after them.
        let mut late = result.clone();
        let first = result.estimates.first().map_or(0.0, |e| e.t);
        late.estimates.retain(|e| e.t > first + LATE_S);
        let ate = se3(&late).ok();
        format!(
            "{}\n  from EuRoC's calibration: rotation {dr:.3}°, translation {:.1} mm, time offset {:.3} ms; \
             {LATE_S} s after the first estimate: ATE {}, rotation RMSE {}",
            est.line(),
            dt * 1e3,
            (est.time_offset_s + shift) * 1e3,
            ate.as_ref().map_or("—".into(), |e| format!("{:.3} m", e.metrics.ate_rmse_m)),
            ate.as_ref().map_or("—".into(), |e| format!(
                "{:.2}° ({:.2}° with the orientations aligned)",
                e.metrics.rotation_rmse_deg, e.metrics.rotation_rmse_oriented_deg
            )),
        )
    });
    let start_note = cuts.from.map(|from| {
        let starts: Vec<&str> = result
            .warnings
            .iter()
            .filter(|w| w.starts_with("initialized") || w.contains("contradicted by the features"))
            .map(|w| w.as_str())
            .collect();
        format!("from {from} s: {}", starts.join("; "))
    });
    let note = [note, blackout_note, start_note].into_iter().flatten().collect::<Vec<_>>();
    let note = (!note.is_empty()).then(|| note.join("\n  "));
    Ok(Some((summary, note)))
}

fn print_table(rows: &[(String, Summary)], markdown: bool) {
    let head = [
        "sequence",
        "ATE m",
        "RPE %",
        "RPE °",
        "rot RMSE °",
        "rot RMSE ° (orientations aligned)",
        "bias RMSE g, a",
        "÷ floor g, a",
        "NEES gyro x y z",
        "NEES accel x y z",
        "noise in use g, a",
        "resets",
        "× real time",
    ];
    let f3 = |v: Option<[f64; 3]>| v.map_or("—".into(), |v| format!("{:.1} {:.1} {:.1}", v[0], v[1], v[2]));
    let lines: Vec<Vec<String>> = rows
        .iter()
        .map(|(name, s)| {
            let m = s.evaluation.as_ref().map(|e| &e.metrics);
            let rpe = m.and_then(|m| m.rpe.first());
            let ratios = s.bias_rmse_ratios();
            vec![
                name.clone(),
                s.ate_rmse_m.map_or("—".into(), |x| format!("{x:.3}")),
                rpe.map_or("—".into(), |r| format!("{:.2}", r.trans_mean_percent)),
                rpe.map_or("—".into(), |r| format!("{:.2}", r.rot_mean_deg)),
                m.map_or("—".into(), |m| format!("{:.2}", m.rotation_rmse_deg)),
                m.map_or("—".into(), |m| format!("{:.2}", m.rotation_rmse_oriented_deg)),
                match (s.bias_rmse_gyro, s.bias_rmse_accel) {
                    (Some(g), Some(a)) => format!("{g:.1e}, {a:.3}"),
                    _ => "—".into(),
                },
                ratios.map_or("—".into(), |(g, a)| format!("{g:.1}×, {a:.1}×")),
                f3(m.and_then(|m| m.bias_nees_gyro_axes)),
                f3(m.and_then(|m| m.bias_nees_accel_axes)),
                s.noise.map_or("given".into(), |n| format!("{:.1e}, {:.1e}", n.in_use[0], n.in_use[1])),
                match s.starts.len() {
                    0 | 1 => s.resets.to_string(),
                    n => format!("{} ({n} pieces)", s.resets),
                },
                format!("{:.0}", s.realtime_factor),
            ]
        })
        .collect();
    if markdown {
        println!("| {} |", head.join(" | "));
        println!("|{}", "---|".repeat(head.len()));
        for l in &lines {
            println!("| {} |", l.join(" | "));
        }
        return;
    }
    let widths: Vec<usize> = (0..head.len())
        .map(|k| lines.iter().map(|l| l[k].chars().count()).chain([head[k].chars().count()]).max().unwrap_or(0))
        .collect();
    let row = |cells: Vec<String>| {
        cells.iter().zip(&widths).map(|(c, w)| format!("{c:<w$}")).collect::<Vec<_>>().join("  ").trim_end().to_string()
    };
    println!("{}", row(head.iter().map(|s| s.to_string()).collect()));
    for l in lines {
        println!("{}", row(l));
    }
}
