//! Helpers of the VIO tests.

use tumble::sim::{simulate, Scenario, SimConfig};
use tumble::vio::{run, summarize, Summary, VioInput, VioOptions, VioResult};

pub fn simulated(scenario: Scenario, duration: f64, seed: u64) -> (VioInput, VioOptions) {
    let cfg = SimConfig { duration_s: Some(duration), ..SimConfig::default() };
    let sim = simulate(scenario, &cfg, seed).unwrap();
    (VioInput::from_simulation(&sim).unwrap(), VioOptions::for_simulation(&cfg))
}

pub fn walk(duration: f64, seed: u64) -> (VioInput, VioOptions) {
    simulated(Scenario::Walk, duration, seed)
}

/// Index of the first ground-truth sample at or after input time `t` \[s\]
/// (the last one past the end).
pub fn truth_index(input: &VioInput, t: f64) -> usize {
    let gt = input.groundtruth.as_ref().expect("ground truth");
    gt.t_ns.partition_point(|&s| s < input.t0_ns + (t * 1e9).round() as i64).min(gt.len() - 1)
}

/// Run the estimator, print its summary (bias errors from `bias_after` s) and
/// check that it never reset.
pub fn run_without_resets(input: &VioInput, opts: &VioOptions, bias_after: f64) -> (VioResult, Summary) {
    let out = run(input, opts, None).unwrap();
    let s = summarize(input, opts, &out, bias_after);
    println!("{}", s.table());
    assert_eq!(out.resets, 0, "{:?}", out.warnings);
    (out, s)
}

pub fn finite(out: &tumble::vio::VioResult) -> bool {
    out.estimates.iter().all(|e| e.position.iter().chain(&e.velocity).chain(&e.bias_accel).all(|x| x.is_finite()))
}

/// A walk whose recording starts `skip` seconds in, while moving (the
/// simulated walk rests 3 s, then ramps up over 2 s).
pub fn walk_started_in_motion(duration: f64, seed: u64, skip: f64) -> (VioInput, VioOptions) {
    let (mut input, opts) = walk(duration, seed);
    input.drop_before(skip);
    (input, opts)
}
