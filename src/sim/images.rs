//! A simulation's camera frames rendered into its ASL folder
//! (`camN/data/<stamp>.png`, listed in `camN/data.csv`), for `tumble sim
//! <scenario> --images`.

use super::render::{lens::RayTable, render_frame, scene::RenderScene, ImageSettings};
use super::{CameraSettings, Motion, Scene, SimError, Simulation};
use crate::io::convert::encode_png;
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Duration;

/// The scene a simulation's camera sees, as textured planes.
pub fn render_scene(sim: &Simulation) -> RenderScene {
    match sim.scene {
        Scene::Room(centre) => RenderScene::room(centre, sim.config.camera.room_half_extent, sim.seed),
        Scene::Corridor(c) => RenderScene::corridor(&c, sim.seed),
    }
}

/// Whether `scenario` under `config` has frames that can be rendered:
/// refused before anything is simulated when it has no camera.
pub fn check_renderable(scenario: super::Scenario, config: &super::SimConfig) -> Result<(), SimError> {
    if !config.has_camera(scenario) {
        return Err(
            format!("images: the {scenario:?} scenario has no camera (walk, flight and corridor have one)").into()
        );
    }
    Ok(())
}

/// Render every frame of every simulated camera of `sim` with `settings`
/// into `out/mav0/camN/data/<stamp>.png` (the stamps of `camN/data.csv`),
/// calling `progress(done, total)` after each frame. Errors: a simulation
/// without a camera, a file not written.
pub fn write_images(
    sim: &Simulation,
    settings: &ImageSettings,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), SimError> {
    settings.check()?;
    let tracks =
        sim.tracks.as_ref().ok_or("images: the scenario has no camera (walk, flight and corridor have one)")?;
    let scene = render_scene(sim);
    let c = &sim.config.camera;
    let stamp = |t: f64| sim.stamp_ns(t);
    render_cameras(&scene, c, sim.motion.as_ref(), &tracks.frames, &stamp, settings, sim.seed, out, progress)
}

/// Render the frames at `frame_times` \[s\], each stamped `stamp_ns(t)`, of
/// camera `c` and, with a stereo baseline, of its second camera, carried
/// along `motion` through `scene`, into `out/mav0/camN/data/<stamp>.png`;
/// `progress(done, total)` after each batch.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_cameras(
    scene: &RenderScene,
    c: &CameraSettings,
    motion: &dyn Motion,
    frame_times: &[f64],
    stamp_ns: &dyn Fn(f64) -> i64,
    settings: &ImageSettings,
    seed: u64,
    out: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), SimError> {
    // Each frame exposed at its stamp plus the camera's time offset (IMU time).
    let frames: Vec<(f64, i64)> = frame_times.iter().map(|&t| (t + c.time_offset_s, stamp_ns(t))).collect();
    let frames = &frames[..];
    let mut cameras: Vec<Isometry3<f64>> = vec![c.body_from_camera()];
    if c.stereo_baseline_m > 0.0 {
        cameras.push(c.body_from_second_camera());
    }
    let mut progress = Progress { done: 0, total: frames.len() * cameras.len(), report: progress };
    for (index, body_from_camera) in cameras.iter().enumerate() {
        let camera = CameraFrames { scene, camera: c, motion, body_from_camera, settings, seed, index };
        camera.render(frames, &out.join("mav0").join(format!("cam{index}")).join("data"), &mut progress)?;
    }
    Ok(())
}

/// Frames rendered so far of how many, and whom to tell.
pub(crate) struct Progress<'a> {
    /// Frames written.
    pub done: usize,
    /// Frames to write.
    pub total: usize,
    /// Called with `(done, total)` as frames are written.
    pub report: &'a mut dyn FnMut(usize, usize),
}

/// What one camera's frames are rendered from.
pub(crate) struct CameraFrames<'a> {
    /// The scene.
    pub scene: &'a RenderScene,
    /// The camera's lens, resolution and focal length.
    pub camera: &'a CameraSettings,
    /// The body's motion (IMU time).
    pub motion: &'a dyn Motion,
    /// Camera to body.
    pub body_from_camera: &'a Isometry3<f64>,
    /// Exposure, noise and gain.
    pub settings: &'a ImageSettings,
    /// The recording's seed.
    pub seed: u64,
    /// The camera's index in the rig (cam0, cam1, …): its own noise and flicker.
    pub index: usize,
}

impl CameraFrames<'_> {
    /// Render `frames` (the IMU time at the middle of each exposure \[s\] and
    /// the frame's stamp \[ns\]) into `dir/<stamp>.png`, rayon across
    /// frames, the progress reported while they render.
    pub fn render(&self, frames: &[(f64, i64)], dir: &Path, progress: &mut Progress) -> Result<(), SimError> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let c = self.camera;
        let [w, h] = c.resolution.map(|x| x as usize);
        let lens = RayTable::new(&c.model(), w, h);
        let focal = c.intrinsics[0].max(c.intrinsics[1]);
        // Each camera flickers on its own (its own auto-exposure).
        let mut gains = ChaCha8Rng::seed_from_u64(self.seed);
        gains.set_stream(300 + self.index as u64);
        let gains: Vec<f64> = (0..frames.len())
            .map(|_| {
                let jitter: f64 = StandardNormal.sample(&mut gains);
                (1.0 + self.settings.gain_jitter * jitter).max(0.0)
            })
            .collect();
        let frame = |k: usize| -> Result<(), String> {
            let (t, stamp) = frames[k];
            let seed = self.seed.wrapping_mul(1_000_003).wrapping_add((self.index * frames.len() + k) as u64);
            let pixels = render_frame(
                self.scene,
                &lens,
                focal,
                self.motion,
                self.body_from_camera,
                t,
                gains[k],
                self.settings,
                seed,
            );
            let path = dir.join(format!("{stamp}.png"));
            let bytes = encode_png(&pixels, w, h, png::ColorType::Grayscale, png::BitDepth::Eight)
                .map_err(|e| format!("{}: {e}", path.display()))?;
            std::fs::write(&path, bytes).map_err(|e| format!("{}: {e}", path.display()))
        };
        let done = AtomicUsize::new(0);
        let first = progress.done;
        let rendered = while_reporting(
            || {
                (0..frames.len())
                    .into_par_iter()
                    .map(|k| {
                        let r = frame(k);
                        done.fetch_add(1, Ordering::Relaxed);
                        r
                    })
                    .collect::<Result<Vec<()>, String>>()
            },
            || (progress.report)(first + done.load(Ordering::Relaxed), progress.total),
        );
        rendered?;
        progress.done = first + frames.len();
        (progress.report)(progress.done, progress.total);
        Ok(())
    }
}

/// How often a long render reports its progress.
const PROGRESS_PERIOD: Duration = Duration::from_millis(100);

/// `work()` (parallel work on the current rayon pool) while the calling
/// thread calls `report()` every [`PROGRESS_PERIOD`]: one parallel loop over
/// every frame keeps both cores busy to the end (batches between reports
/// left one idle while the other finished its batch's slowest frame). On a
/// pool's own thread the caller runs queued work instead of sleeping, so a
/// one-thread pool still makes progress. A panic in `work` is caught, so
/// that the caller stops waiting, and raised again on the calling thread.
fn while_reporting<T: Send>(work: impl FnOnce() -> T + Send, mut report: impl FnMut()) -> T {
    let result = Mutex::new(None);
    rayon::in_place_scope(|s| {
        s.spawn(|_| {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
            *result.lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
        });
        while result.lock().unwrap_or_else(|e| e.into_inner()).is_none() {
            if rayon::yield_now() != Some(rayon::Yield::Executed) {
                std::thread::sleep(PROGRESS_PERIOD);
            }
            report();
        }
    });
    match result.into_inner().unwrap_or_else(|e| e.into_inner()).expect("the scope ran its work") {
        Ok(r) => r,
        Err(panic) => std::panic::resume_unwind(panic),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The work's result comes back and the caller reports while it runs,
    /// from a plain thread and from the only thread of a one-thread pool
    /// (which must run the work itself rather than wait for it).
    #[test]
    fn parallel_work_finishes_and_reports_from_any_thread() {
        let work = || (0..64u64).into_par_iter().map(|k| k * k).sum::<u64>();
        let slow = || {
            std::thread::sleep(3 * PROGRESS_PERIOD);
            work()
        };
        let mut reports = 0;
        assert_eq!(while_reporting(slow, || reports += 1), 85_344);
        assert!(reports >= 2, "{reports} reports over three periods");
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
        assert_eq!(pool.install(|| while_reporting(work, || {})), 85_344);
    }

    /// A panic in the work reaches the caller (it used to leave the caller
    /// waiting for a result that never came).
    #[test]
    fn a_panic_in_the_work_reaches_the_caller() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let caught = std::panic::catch_unwind(|| while_reporting(|| -> u64 { panic!("a frame failed") }, || {}));
            let _ = tx.send(caught.is_err());
        });
        let panicked = rx.recv_timeout(Duration::from_secs(10)).expect("the caller returned within 10 s");
        assert!(panicked);
    }
}
