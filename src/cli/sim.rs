//! `tumble sim`: simulate a recording with known truth.

use super::CliResult;
use clap::Args;
use std::path::PathBuf;
use tumble::sim::{Scenario, SimConfig};

/// Flags of `tumble sim`.
#[derive(Args)]
pub struct SimArgs {
    /// What to simulate: an IMU scenario, or `rig` (a camera–IMU rig waved
    /// before a checkerboard, for `tumble calibrate-rig X --target
    /// X/target.yaml`; its camera is EuRoC's cam0 with a 3 ms time offset;
    /// of --config it reads the `images` key).
    #[arg(value_parser = clap::builder::PossibleValuesParser::new(SCENARIOS))]
    scenario: String,
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
    /// Render the camera's frames as images (walk and flight; cam1 too with
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

/// The scenarios `tumble sim` takes: the IMU scenarios, then `rig`.
const SCENARIOS: [&str; 6] =
    [Scenario::NAMES[0], Scenario::NAMES[1], Scenario::NAMES[2], Scenario::NAMES[3], Scenario::NAMES[4], "rig"];

impl SimArgs {
    pub fn run(self) -> CliResult {
        if self.scenario == "rig" {
            return self.run_rig();
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
        let bar = cfg.images.is_some().then(|| {
            super::common::progress_bar(0, "rendering [{bar:40}] {pos}/{len} frames {elapsed_precise} (eta {eta})")
        });
        let mut progress = |done: usize, total: usize| {
            if let Some(b) = &bar {
                b.set_length(total as u64);
                b.set_position(done as u64);
            }
        };
        let sim = tumble::sim::simulate_and_write_with(scenario, &cfg, self.seed, &out, &mut progress)?;
        if let Some(b) = bar {
            b.finish_and_clear();
        }
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

    /// `tumble sim rig`: the rig recording, its frames rendered with --images.
    fn run_rig(self) -> CliResult {
        let cfg = match &self.config {
            Some(p) => SimConfig::read(p)?,
            None => SimConfig::default(),
        };
        if self.print_config {
            print!("{}", serde_saphyr::to_string(&cfg)?);
            return Ok(());
        }
        if !self.hide.is_empty() || !self.pause.is_empty() {
            return Err("sim rig: --hide and --pause are for the IMU scenarios".into());
        }
        let out = self.out.ok_or("give --out (or --print-config)")?;
        let settings = tumble::sim::rig_recording::rig_settings(
            self.duration.unwrap_or(tumble::sim::target::RigSimSettings::default().duration_s),
            self.stereo_baseline.unwrap_or(0.0),
        );
        let images = match (self.images, cfg.images) {
            (false, _) => None,
            (true, Some(i)) => Some(i),
            (true, None) => Some(tumble::sim::render::ImageSettings::default()),
        };
        let start = std::time::Instant::now();
        let bar = images.is_some().then(|| {
            super::common::progress_bar(0, "rendering [{bar:40}] {pos}/{len} frames {elapsed_precise} (eta {eta})")
        });
        let mut progress = |done: usize, total: usize| {
            if let Some(b) = &bar {
                b.set_length(total as u64);
                b.set_position(done as u64);
            }
        };
        let sim = tumble::sim::rig_recording::write_rig_recording(
            &settings,
            images.as_ref(),
            self.seed,
            &out,
            &mut progress,
        )?;
        if let Some(b) = bar {
            b.finish_and_clear();
        }
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
}
