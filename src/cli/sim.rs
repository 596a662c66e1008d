//! `tumble sim`: simulate a recording with known truth.

use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::sim::{Scenario, SimConfig};

/// Flags of `tumble sim`.
#[derive(Args)]
pub struct SimArgs {
    /// What to simulate: an IMU scenario; `rig` (a camera–IMU rig waved
    /// before a checkerboard or --target, for `tumble calibrate-rig X --target
    /// X/target.yaml`; its camera is EuRoC's cam0 with a 3 ms time offset;
    /// of --config it reads the `images` key); or `replay` (a window of a
    /// real recording, --from, its IMU as recorded and a camera flown along
    /// its ground truth in a box around the path; of --config it reads the
    /// `camera` and `images` keys).
    #[arg(value_parser = clap::builder::PossibleValuesParser::new(SCENARIOS))]
    scenario: String,
    /// The recording `replay` flies its camera through: an ASL folder with
    /// IMU and ground truth (e.g. a EuRoC Machine Hall flight).
    #[arg(long, value_name = "DIR", required_if_eq("scenario", "replay"))]
    from: Option<PathBuf>,
    /// The target `rig` waves its rig before: Kalibr's target.yaml (an
    /// aprilgrid, drawn as Kalibr prints it, or a checkerboard; default: a
    /// checkerboard of 7 × 6 inner corners 8 cm apart).
    #[arg(long, value_name = "YAML")]
    target: Option<PathBuf>,
    /// Where `replay`'s window starts, after the recording's first IMU sample [s]
    /// (0: its start; later: an estimator starts in motion).
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0)]
    start: f64,
    /// Output folder (gets mav0/ and truth.json).
    #[arg(long, required_unless_present = "print_config")]
    out: Option<PathBuf>,
    /// YAML config: IMU model, effects, durations, camera (every key optional).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Random seed; the same seed and config give the same bytes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Length of static, walk, flight and corridor scenarios [s] (overrides the config).
    #[arg(long)]
    duration: Option<f64>,
    /// Add a second camera this far right of cam0 [m] (EuRoC: 0.11): writes
    /// cam1/sensor.yaml and its matches in cam0/tracks_cam1.csv, which
    /// `tumble vio` uses to initialize (overrides the config's
    /// camera.stereo_baseline_m).
    #[arg(long, value_name = "METRES")]
    stereo_baseline: Option<f64>,
    /// Stop a walk, flight or corridor walk on the way: slow down over 1 s from START
    /// seconds, stand still for LENGTH seconds, speed up over 1 s
    /// (repeatable; each makes the recording LENGTH + 1 s longer; overrides
    /// the config's pauses_s).
    #[arg(long, value_name = "START,LENGTH", value_parser = tumble::sim::parse_pause)]
    pause: Vec<[f64; 2]>,
    /// Render the camera's frames as images (walk, flight, corridor, rig and
    /// replay; cam1 too with
    /// --stereo-baseline): camN/data/<stamp>.png, exposed as the config's
    /// `images` key says (defaults: 3 ms exposure, 2 grey levels of read noise,
    /// 25 % vignetting). The simulated tracks then go to truth/ and `tumble vio`
    /// tracks the images (feature `opencv`).
    #[arg(long)]
    images: bool,
    /// Print the default config as YAML and exit (a starting point for --config).
    #[arg(long)]
    print_config: bool,
    /// Hide an effect the calibration model lacks (for `tumble audit`): EFFECT or
    /// EFFECT:STRENGTH with EFFECT one of g_sensitivity, temperature_bias,
    /// temperature_bias_quadratic, temperature_scale, temperature_scale_quadratic,
    /// gyro_nonlinearity, accel_nonlinearity, bias_drift (STRENGTH multiplies the model's
    /// coefficients, default 1), or gyro_nonlinearity_FORM / accel_nonlinearity_FORM with
    /// FORM one of even, odd, cubic, asymmetric (STRENGTH: deviation at full scale in % of
    /// full scale) (repeatable).
    #[arg(long)]
    hide: Vec<String>,
}

/// The scenarios `tumble sim` takes: the IMU scenarios, then `rig` and `replay`.
const SCENARIOS: [&str; 7] = [
    Scenario::NAMES[0],
    Scenario::NAMES[1],
    Scenario::NAMES[2],
    Scenario::NAMES[3],
    Scenario::NAMES[4],
    "rig",
    "replay",
];

impl SimArgs {
    pub fn run(self) -> CliResult {
        if self.scenario != "replay" && (self.from.is_some() || self.start != 0.0) {
            return Err("sim: --from and --start are for the replay scenario".into());
        }
        if self.scenario != "rig" && self.target.is_some() {
            return Err("sim: --target is for the rig scenario".into());
        }
        match self.scenario.as_str() {
            "rig" => return self.run_rig(),
            "replay" => return self.run_replay(),
            _ => {}
        }
        let scenario: Scenario = self.scenario.parse()?;
        let mut cfg = match &self.config {
            Some(p) => SimConfig::read(p)?,
            None => SimConfig::default(),
        };
        for h in &self.hide {
            tumble::sim::hide_effect_spec(&mut cfg, h)?;
        }
        if self.print_config {
            print!("{}", serde_saphyr::to_string(&cfg)?);
            return Ok(());
        }
        let out = self.out.ok_or("give --out (or --print-config)")?;
        if self.duration.is_some() {
            cfg.duration_s = self.duration;
        }
        if !self.pause.is_empty() {
            cfg.pauses_s = self.pause;
        }
        if let Some(b) = self.stereo_baseline {
            cfg.camera.stereo_baseline_m = b;
        }
        if self.images && cfg.images.is_none() {
            cfg.images = Some(tumble::sim::render::ImageSettings::default());
        }
        let start = std::time::Instant::now();
        let bar = RenderBar::new(cfg.images.is_some());
        let sim = tumble::sim::simulate_and_write_with(scenario, &cfg, self.seed, &out, &mut |d, t| bar.update(d, t))?;
        bar.finish();
        println!(
            "simulated {:?}: {} IMU samples over {:.1} s{}, written to {} in {:.2} s",
            scenario,
            sim.imu.t.len(),
            sim.motion.duration(),
            sim.tracks
                .as_ref()
                .map(|t| format!(", {} frames, {} feature observations", t.frames.len(), t.observations.len()))
                .unwrap_or_default(),
            out.display(),
            start.elapsed().as_secs_f64()
        );
        Ok(())
    }

    /// The config of `rig` and `replay` (`--config` or the defaults) and the
    /// output folder; None when the config was printed (`--print-config`).
    /// Errors: flags of the simulated IMU scenarios, no `--out`.
    fn camera_recording_config(&self) -> Result<Option<(SimConfig, PathBuf)>, Box<dyn std::error::Error>> {
        let cfg = match &self.config {
            Some(p) => SimConfig::read(p)?,
            None => SimConfig::default(),
        };
        if self.print_config {
            print!("{}", serde_saphyr::to_string(&cfg)?);
            return Ok(None);
        }
        if !self.hide.is_empty() || !self.pause.is_empty() {
            return Err(format!("sim {}: --hide and --pause are for the simulated IMU scenarios", self.scenario).into());
        }
        let out = self.out.clone().ok_or("give --out (or --print-config)")?;
        Ok(Some((cfg, out)))
    }

    /// `tumble sim rig`: the rig recording, its frames rendered with --images.
    fn run_rig(self) -> CliResult {
        let Some((cfg, out)) = self.camera_recording_config()? else { return Ok(()) };
        let mut settings = tumble::sim::rig_recording::rig_settings(
            self.duration.unwrap_or(tumble::sim::target::RigSimSettings::default().duration_s),
            self.stereo_baseline.unwrap_or(0.0),
        );
        if let Some(path) = &self.target {
            settings.target = tumble::rig::Target::read(path)?;
        }
        let images = self.images.then(|| cfg.images.unwrap_or_default());
        let start = std::time::Instant::now();
        let bar = RenderBar::new(images.is_some());
        let sim = tumble::sim::rig_recording::write_rig_recording(
            &settings,
            images.as_ref(),
            self.seed,
            &out,
            &mut |d, t| bar.update(d, t),
        )?;
        bar.finish();
        let views: usize = sim.input.cameras.iter().map(|c| c.views.len()).sum();
        println!(
            "simulated rig: {} IMU samples over {:.1} s, {} camera(s), {views} {}, written to {} in {:.2} s \
             (calibrate: tumble calibrate-rig {} --target {})",
            sim.input.imu.t.len(),
            settings.duration_s,
            sim.input.cameras.len(),
            if images.is_some() { "rendered frames" } else { "views of the target's corners" },
            out.display(),
            start.elapsed().as_secs_f64(),
            out.display(),
            out.join("target.yaml").display()
        );
        Ok(())
    }

    /// `tumble sim replay`: a window of a real recording with a simulated camera.
    fn run_replay(self) -> CliResult {
        let Some((cfg, out)) = self.camera_recording_config()? else { return Ok(()) };
        let source = self.from.ok_or("sim replay: give the recording with --from DIR")?;
        let mut camera = cfg.camera;
        if let Some(b) = self.stereo_baseline {
            camera.stereo_baseline_m = b;
        }
        let images = self.images.then(|| cfg.images.unwrap_or_default());
        let settings = tumble::sim::replay_recording::ReplaySettings {
            start_s: self.start,
            duration_s: self.duration,
            camera,
            images,
            seed: self.seed,
        };
        let start = std::time::Instant::now();
        let bar = RenderBar::new(settings.images.is_some());
        let done =
            tumble::sim::replay_recording::replay_and_write(&source, &settings, &out, &mut |d, t| bar.update(d, t))?;
        bar.finish();
        for note in &done.notes {
            println!("note: {note}");
        }
        let h = done.scene_half_extent;
        println!(
            "replayed {} over {:.1}–{:.1} s: {} IMU samples, {} {} ({} feature observations) in a {:.0} × {:.0} × {:.0} m \
             box, written to {} in {:.2} s",
            source.display(),
            done.window_s[0],
            done.window_s[1],
            done.imu_samples,
            done.frames,
            if settings.images.is_some() { "rendered frames" } else { "frames of feature tracks" },
            done.observations,
            2.0 * h[0],
            2.0 * h[1],
            2.0 * h[2],
            out.display(),
            start.elapsed().as_secs_f64()
        );
        Ok(())
    }
}

/// A progress bar over rendered frames, shown only when frames are rendered.
struct RenderBar(Option<indicatif::ProgressBar>);

impl RenderBar {
    fn new(shown: bool) -> RenderBar {
        RenderBar(shown.then(|| {
            super::common::progress_bar(0, "rendering [{bar:40}] {pos}/{len} frames {elapsed_precise} (eta {eta})")
        }))
    }
    /// `done` of `total` frames rendered.
    fn update(&self, done: usize, total: usize) {
        if let Some(b) = &self.0 {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    }
    fn finish(self) {
        if let Some(b) = self.0 {
            b.finish_and_clear();
        }
    }
}
