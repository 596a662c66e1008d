//! IMU samples from a [`Motion`] and an [`ImuModel`]: every random process
//! has its own ChaCha8 stream derived from the seed, so the same seed gives
//! the same samples whatever the thread count.

use super::model::{flicker_components_per_decade, ImuModel, TriadModel};
use super::motion::Motion;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

/// Simulated measurements with the true biases behind them.
#[derive(Debug, Clone, Default)]
pub struct SimulatedImu {
    /// Stamps \[s\] (uniform; the true sampling instants jitter around them when jitter is on).
    pub t: Vec<f64>,
    /// Gyro measurements \[rad/s\].
    pub gyro: Vec<[f64; 3]>,
    /// Accelerometer measurements \[m/s²\].
    pub accel: Vec<[f64; 3]>,
    /// Sensor temperature \[°C\] (when the temperature effect is on).
    pub temperature: Option<Vec<f64>>,
    /// The true biases are kept for every `bias_every`-th sample (index `i · bias_every`).
    pub bias_every: usize,
    /// True additive gyro bias (turn-on + random walk + instability + temperature) \[rad/s\].
    pub bias_gyro: Vec<[f64; 3]>,
    /// True additive accelerometer bias \[m/s²\].
    pub bias_accel: Vec<[f64; 3]>,
}

impl SimulatedImu {
    /// The measurements as an in-memory [`crate::io::ImuRecording`] (SI units,
    /// stamps from 0 s; source name `<simulation>`), as a reader would return them.
    pub fn to_recording(&self) -> crate::io::ImuRecording {
        crate::io::ImuRecording {
            sources: vec!["<simulation>".into()],
            t: self.t.clone(),
            gyro: self.gyro.clone(),
            accel: self.accel.clone(),
            temperature: self.temperature.clone(),
            ..Default::default()
        }
    }
}

fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// The random processes of one axis, advanced chunk by chunk: bias (turn-on +
/// random walk + flicker as Gauss–Markov sum) and white noise.
struct AxisGen {
    rng: ChaCha8Rng,
    turn_on: f64,
    rw_step: f64,
    rw: f64,
    drift_step: f64,
    drift: f64,
    gm: Vec<(f64, f64, f64)>, // (φ, innovation std, state)
    white: f64,
}

impl AxisGen {
    fn new(t: &TriadModel, k: usize, m: &ImuModel, seed: u64, stream: u64) -> AxisGen {
        let e = &m.effects;
        let dt = 1.0 / m.rate_hz;
        let mut rng = rng(seed, stream);
        let mut gm = Vec::new();
        if e.bias_instability && t.bias_instability[k] > 0.0 {
            let (tcs, q) = flicker_components_per_decade(t.bias_instability[k], t.bias_instability_band, 1);
            for tc in tcs {
                let phi = (-dt / tc).exp();
                let x0: f64 = q * Distribution::<f64>::sample(&StandardNormal, &mut rng);
                gm.push((phi, q * (1.0 - phi * phi).sqrt(), x0));
            }
        }
        AxisGen {
            rng,
            turn_on: if e.bias { t.bias[k] } else { 0.0 },
            rw_step: if e.random_walk { t.random_walk[k] * dt.sqrt() } else { 0.0 },
            rw: 0.0,
            drift_step: if e.bias_drift { t.bias_drift[k] * dt } else { 0.0 },
            drift: 0.0,
            gm,
            white: if e.white_noise { t.noise_density[k] * m.rate_hz.sqrt() } else { 0.0 },
        }
    }

    /// Fill the next `bias.len()` samples.
    fn fill(&mut self, bias: &mut [f64], noise: &mut [f64]) {
        let normal = |r: &mut ChaCha8Rng| -> f64 { StandardNormal.sample(r) };
        for (b, nz) in bias.iter_mut().zip(noise.iter_mut()) {
            let mut x = self.turn_on + self.rw + self.drift;
            self.drift += self.drift_step;
            if self.rw_step > 0.0 {
                self.rw += self.rw_step * normal(&mut self.rng);
            }
            for g in self.gm.iter_mut() {
                x += g.2;
                g.2 = g.0 * g.2 + g.1 * normal(&mut self.rng);
            }
            *b = x;
            *nz = if self.white > 0.0 { self.white * normal(&mut self.rng) } else { 0.0 };
        }
    }
}
/// What a triad outputs for true input `x` (before bias, noise, clipping).
fn deterministic(t: &TriadModel, m: &ImuModel, x: [f64; 3], dtemp: f64) -> [f64; 3] {
    let e = &m.effects;
    let mut y = x;
    if e.nonlinearity {
        for k in 0..3 {
            y[k] += t.nonlinearity[k] * t.nonlinearity_form.eval(x[k]);
        }
    }
    for (k, yk) in y.iter_mut().enumerate() {
        let mut s = if e.scale { t.scale[k] } else { 1.0 };
        if e.temperature {
            s *= 1.0 + t.temperature_scale[k] * dtemp + t.temperature_scale_quadratic[k] * dtemp * dtemp;
        }
        *yk *= s;
    }
    if e.misalignment {
        let a = &t.misalignment;
        y = [0, 1, 2].map(|r| a[r][0] * y[0] + a[r][1] * y[1] + a[r][2] * y[2]);
    }
    y
}

fn finish(t: &TriadModel, m: &ImuModel, mut v: f64) -> f64 {
    if m.effects.saturation && t.range < f64::MAX {
        v = v.clamp(-t.range, t.range);
    }
    if m.effects.quantization && t.lsb > 0.0 {
        v = (v / t.lsb).round() * t.lsb;
    }
    v
}

/// Simulate the IMU over the whole motion at `model.rate_hz` under gravity
/// `g` \[m/s²\], keeping the true biases of every `bias_every`-th sample.
///
/// Works in chunks of 64 Ki samples (the six axes' processes in parallel, then
/// the samples in parallel), so memory is the output plus one chunk.
pub fn simulate_imu(motion: &dyn Motion, model: &ImuModel, g: f64, seed: u64, bias_every: usize) -> SimulatedImu {
    simulate_imu_streaming(motion, model, g, seed, bias_every, &mut |_, _| {})
}

/// [`simulate_imu`], calling `on_chunk(samples so far, range)` after each
/// chunk is final, so a writer can stream it out while the next is simulated.
pub fn simulate_imu_streaming(
    motion: &dyn Motion,
    model: &ImuModel,
    g: f64,
    seed: u64,
    bias_every: usize,
    on_chunk: &mut dyn FnMut(&SimulatedImu, std::ops::Range<usize>),
) -> SimulatedImu {
    let bias_every = bias_every.max(1);
    let dt = 1.0 / model.rate_hz;
    let n = (motion.duration() * model.rate_hz).floor() as usize + 1;
    let e = &model.effects;
    let jitter_on = e.jitter && model.jitter_s > 0.0;
    let mut jitter_rng = jitter_on.then(|| rng(seed, 100));
    let mut gens: Vec<AxisGen> = (0..6)
        .map(|a| AxisGen::new(if a < 3 { &model.gyro } else { &model.accel }, a % 3, model, seed, 1 + a as u64))
        .collect();
    let mut out = SimulatedImu {
        t: (0..n).map(|i| i as f64 * dt).collect(),
        gyro: vec![[0.0; 3]; n],
        accel: vec![[0.0; 3]; n],
        temperature: e.temperature.then(|| (0..n).map(|i| model.temperature.at(i as f64 * dt)).collect()),
        bias_every,
        bias_gyro: Vec::with_capacity(n / bias_every + 1),
        bias_accel: Vec::with_capacity(n / bias_every + 1),
    };
    const CHUNK: usize = 1 << 16;
    let mut bias = vec![vec![0.0; CHUNK]; 6];
    let mut noise = vec![vec![0.0; CHUNK]; 6];
    let mut jitter = vec![0.0; CHUNK];
    let tref = model.temperature.reference;
    for c0 in (0..n).step_by(CHUNK) {
        let len = CHUNK.min(n - c0);
        gens.par_iter_mut().zip(bias.par_iter_mut()).zip(noise.par_iter_mut()).for_each(|((gen, b), nz)| {
            gen.fill(&mut b[..len], &mut nz[..len]);
        });
        if let Some(r) = jitter_rng.as_mut() {
            for j in jitter[..len].iter_mut() {
                *j = model.jitter_s * Distribution::<f64>::sample(&StandardNormal, r);
            }
        }
        let temperature = out.temperature.as_deref();
        let (bias, noise, jitter) = (&bias, &noise, &jitter);
        out.gyro[c0..c0 + len]
            .par_iter_mut()
            .zip(out.accel[c0..c0 + len].par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(j, (gyro, accel))| {
                let i = c0 + j;
                let ti = (i as f64 * dt + if jitter_on { jitter[j] } else { 0.0 }).clamp(0.0, motion.duration());
                let k = motion.at(ti);
                let f = if model.accel_time_offset_s == 0.0 {
                    k.specific_force(g)
                } else {
                    motion.at((ti + model.accel_time_offset_s).clamp(0.0, motion.duration())).specific_force(g)
                };
                let (w, f) = ([k.omega.x, k.omega.y, k.omega.z], [f.x, f.y, f.z]);
                let dtemp = temperature.map(|v| v[i] - tref).unwrap_or(0.0);
                let yg = deterministic(&model.gyro, model, w, dtemp);
                let ya = deterministic(&model.accel, model, f, dtemp);
                for k in 0..3 {
                    let (bg, ba) = total_bias(model, bias, k, j, dtemp);
                    let gs = if e.g_sensitivity {
                        let gr = &model.g_sensitivity[k];
                        gr[0] * f[0] + gr[1] * f[1] + gr[2] * f[2]
                    } else {
                        0.0
                    };
                    gyro[k] = finish(&model.gyro, model, yg[k] + bg + gs + noise[k][j]);
                    accel[k] = finish(&model.accel, model, ya[k] + ba + noise[3 + k][j]);
                }
            });
        for j in (0..len).filter(|j| (c0 + j) % bias_every == 0) {
            let dtemp = temperature.map(|v| v[c0 + j] - tref).unwrap_or(0.0);
            let pairs = [0, 1, 2].map(|k| total_bias(model, bias, k, j, dtemp));
            out.bias_gyro.push(pairs.map(|p| p.0));
            out.bias_accel.push(pairs.map(|p| p.1));
        }
        on_chunk(&out, c0..c0 + len);
    }
    out
}

/// Gyro and accelerometer additive bias of axis `k` at chunk offset `j`, with the temperature term.
fn total_bias(model: &ImuModel, bias: &[Vec<f64>], k: usize, j: usize, dtemp: f64) -> (f64, f64) {
    let (mut bg, mut ba) = (bias[k][j], bias[3 + k][j]);
    if model.effects.temperature {
        let poly = |t: &super::model::TriadModel| {
            t.temperature_bias[k] * dtemp + t.temperature_bias_quadratic[k] * dtemp * dtemp
        };
        bg += poly(&model.gyro);
        ba += poly(&model.accel);
    }
    (bg, ba)
}

/// The random error terms of one sensor axis, for [`noise_series`]; units as
/// in [`TriadModel`] (rad/s-based for a gyro, m/s²-based for an accelerometer).
#[derive(Clone, Debug, PartialEq)]
pub struct AxisNoise {
    /// White noise density N \[unit/√Hz\].
    pub noise_density: f64,
    /// Rate random walk K \[unit·√Hz/s\].
    pub random_walk: f64,
    /// Bias instability B \[unit\] (flicker floor 0.664·B, realized as a sum
    /// of Gauss–Markov processes, three per decade of `bias_instability_band`).
    pub bias_instability: f64,
    /// Correlation-time band of the flicker floor \[s\].
    pub bias_instability_band: [f64; 2],
    /// Quantization noise Q \[unit·s\] of the *integrated* output (white phase
    /// noise of std Q on the angle; Q = δ/√12 for an angle quantum δ).
    pub angle_quantization: f64,
}

/// `n` samples at `rate_hz` of one static axis with exactly these random
/// errors and nothing else (no bias, scale or rate quantization): the signal
/// with known Allan coefficients for testing noise identification.
///
/// Each sample is the exact *average over its sample interval* of the
/// continuous-time processes (white noise, Brownian rate random walk,
/// Ornstein–Uhlenbeck components of the flicker floor, each drawn jointly
/// with its state), so the Allan variance of the output is the textbook
/// continuous-time one at every τ = m/rate, even for correlation times
/// shorter than the sample period.
pub fn noise_series(spec: &AxisNoise, rate_hz: f64, n: usize, seed: u64) -> Vec<f64> {
    let dt = 1.0 / rate_hz;
    let mut rng = rng(seed, 0);
    let mut normal = move || -> f64 { StandardNormal.sample(&mut rng) };
    // Ornstein–Uhlenbeck components: (φ, sd of the state innovation, gain of
    // the state innovation in the interval integral, sd of the rest, tc·(1−φ), state).
    let mut ou: Vec<[f64; 6]> = Vec::new();
    if spec.bias_instability > 0.0 {
        let (tcs, q) = flicker_components_per_decade(spec.bias_instability, spec.bias_instability_band, 3);
        for tc in tcs {
            let x = dt / tc;
            let phi = (-x).exp();
            let one_minus_phi = -(-x).exp_m1();
            let v1 = q * q * -(-2.0 * x).exp_m1();
            let v2 = q * q * tc * tc * super::model::gauss_markov_shape(x);
            let c = q * q * tc * one_minus_phi * one_minus_phi;
            let gain = c / v1;
            let rest = (v2 - c * gain).max(0.0).sqrt();
            ou.push([phi, v1.sqrt(), gain, rest, tc * one_minus_phi, q * normal()]);
        }
    }
    let white = spec.noise_density / dt.sqrt();
    let (rw_step, rw_bridge) = (spec.random_walk * dt.sqrt(), spec.random_walk * (dt / 12.0).sqrt());
    let q = spec.angle_quantization;
    let mut rw = 0.0;
    let mut prev_angle_error = q * normal();
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let mut v = white * normal();
        // Random walk: interval average = start + half the step + bridge term.
        let step = rw_step * normal();
        v += rw + 0.5 * step + rw_bridge * normal();
        rw += step;
        for c in ou.iter_mut() {
            let e1 = c[1] * normal();
            let integral = c[4] * c[5] + c[2] * e1 + c[3] * normal();
            v += integral / dt;
            c[5] = c[0] * c[5] + e1;
        }
        if q > 0.0 {
            let next = q * normal();
            v += (next - prev_angle_error) / dt;
            prev_angle_error = next;
        }
        out.push(v);
    }
    out
}
