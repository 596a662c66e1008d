//! Pose graphs: synthetic ones with known truth (the solver's demo and test
//! data), plots, and the two-stage solve of a g2o file.

pub use tumble_factors::testing::{simulate_helix, SimulatedPoseGraph};
use tumble_solvers::sophus_lie::Isometry3F64;

use crate::io::{bal, g2o};
use crate::plot::PlotError;
use std::path::Path;
use tumble_solvers::{Graph, LmOptions, Optimizer, SolveError, Summary, Values};

/// The cost of each 3-D g2o edge in [`solve_file`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EdgeErrorChoice {
    /// Log(Z⁻¹ X₁⁻¹ X₂), GTSAM's BetweenFactor.
    #[default]
    Log,
    /// Ceres' `pose_graph_3d` error.
    Ceres,
    /// Ceres' error first, then the log error from its solution ([`solve_two_stage`]).
    CeresThenLog,
}

/// Settings of [`solve_file`].
#[derive(Debug, Clone, Default)]
pub struct SolveFileOptions {
    /// The optimizer's settings (BAL problems eliminate their points, `l`).
    pub lm: LmOptions,
    /// g2o: repair non-positive-definite information matrices instead of refusing the file.
    pub repair_information: bool,
    /// g2o: the cost of each 3-D edge.
    pub edge_error: EdgeErrorChoice,
    /// A top-view figure will be asked for: refused up front for BAL files.
    pub plot: bool,
}

/// A solved g2o or BAL file.
#[derive(Debug)]
pub struct SolvedFile {
    /// The file's starting values.
    pub initial: Values,
    /// Cost at the start, in the error solved last.
    pub initial_cost: f64,
    /// The solution.
    pub solution: Values,
    /// The (last) solve's summary.
    pub summary: Summary,
    /// The first stage's summary of a two-stage solve.
    pub first_stage: Option<Summary>,
    /// The readers' warnings (e.g. repaired information matrices).
    pub warnings: Vec<String>,
}

impl SolvedFile {
    /// [`plot_top_view`] of the start and the solution, titled with the file's name and χ².
    pub fn plot_top_view(&self, file: &Path, png: &Path) -> Result<(), PlotError> {
        let name = file.file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let title = format!("{name}: χ² {:.1} → {:.1}", 2.0 * self.initial_cost, 2.0 * self.summary.final_cost);
        plot_top_view(&self.initial, &self.solution, &title, png)
    }
}

/// Why a file cannot be solved.
#[derive(Debug, thiserror::Error)]
pub enum PoseGraphError {
    /// The file is wrong (named with its line).
    #[error(transparent)]
    File(#[from] crate::InputError),
    /// The solver failed.
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// An option does not fit the file.
    #[error(transparent)]
    Options(#[from] crate::OptionError),
}

/// Read and solve a g2o pose graph (`.g2o`) or a BAL problem (any other
/// extension), telling `describe` what the file holds before the solve.
pub fn solve_file(
    file: &Path,
    opts: &SolveFileOptions,
    describe: &mut dyn FnMut(String),
) -> Result<SolvedFile, PoseGraphError> {
    let is_g2o = file.extension().is_some_and(|e| e.eq_ignore_ascii_case("g2o"));
    if opts.plot && !is_g2o {
        return Err(crate::OptionError::new(
            "--plot",
            format!("draws pose graphs (.g2o); {} is a BAL problem", file.display()),
        )
        .into());
    }
    if !is_g2o {
        let p = bal::read_bal(file)?;
        describe(format!(
            "{}: BAL problem, {} cameras, {} points, {} observations",
            file.display(),
            p.cameras,
            p.points,
            p.observations
        ));
        let lm = LmOptions { eliminate: vec!['l'], ..opts.lm.clone() };
        let (solution, summary) = Optimizer::new(lm).optimize(&p.graph, &p.values)?;
        let initial_cost = summary.initial_cost;
        return Ok(SolvedFile {
            initial: p.values,
            initial_cost,
            solution,
            summary,
            first_stage: None,
            warnings: Vec::new(),
        });
    }
    let read = |edge_error| {
        let bad_information =
            if opts.repair_information { g2o::BadInformation::Repair } else { g2o::BadInformation::Refuse };
        g2o::read_g2o(file, &g2o::G2oOptions { bad_information, edge_error })
    };
    let pg = read(match opts.edge_error {
        EdgeErrorChoice::Log => g2o::EdgeError::Log,
        EdgeErrorChoice::Ceres | EdgeErrorChoice::CeresThenLog => g2o::EdgeError::CeresQuaternion,
    })?;
    describe(format!("{}: {:?} pose graph, {} vertices, {} edges", file.display(), pg.kind, pg.vertices, pg.edges));
    if opts.edge_error == EdgeErrorChoice::CeresThenLog {
        let log = read(g2o::EdgeError::Log)?;
        let (solution, first, second) = solve_two_stage(&pg.graph, &log.graph, &pg.values, &opts.lm)?;
        let initial_cost = log.graph.cost(&pg.values)?;
        return Ok(SolvedFile {
            initial: pg.values,
            initial_cost,
            solution,
            summary: second,
            first_stage: Some(first),
            warnings: pg.warnings,
        });
    }
    let (solution, summary) = Optimizer::new(opts.lm.clone()).optimize(&pg.graph, &pg.values)?;
    let initial_cost = summary.initial_cost;
    Ok(SolvedFile { initial: pg.values, initial_cost, solution, summary, first_stage: None, warnings: pg.warnings })
}

/// Solve a 3-D pose graph in two stages: first with Ceres' `pose_graph_3d`
/// edge error (`quaternion`, read with
/// [`crate::io::g2o::EdgeError::CeresQuaternion`]), then with the log error
/// (`log`, the same file read with [`crate::io::g2o::EdgeError::Log`]) from
/// the first stage's solution. Both graphs must come from the same file.
/// Returns the solution (a minimum of the log cost) and each stage's summary.
///
/// From the odometry start the two costs can lead to different minima: on
/// torus3D the log error alone stops at χ² 59 900.8, the two stages reach
/// χ² 45 167.1 (in the log cost), the minimum Ceres finds.
///
/// ```no_run
/// use tumble::io::g2o::{read_g2o, EdgeError, G2oOptions};
/// let path = std::path::Path::new("torus3D.g2o");
/// let quat = read_g2o(path, &G2oOptions { edge_error: EdgeError::CeresQuaternion, ..Default::default() }).unwrap();
/// let log = read_g2o(path, &G2oOptions::default()).unwrap();
/// let (solution, first, second) =
///     tumble::posegraph::solve_two_stage(&quat.graph, &log.graph, &quat.values, &Default::default()).unwrap();
/// println!("χ² {:.3} after {} + {} iterations", 2.0 * second.final_cost, first.iterations, second.iterations);
/// ```
pub fn solve_two_stage(
    quaternion: &Graph,
    log: &Graph,
    initial: &Values,
    options: &LmOptions,
) -> Result<(Values, Summary, Summary), SolveError> {
    let optimizer = Optimizer::new(options.clone());
    let (first_solution, first) = optimizer.optimize(quaternion, initial)?;
    let (solution, second) = optimizer.optimize(log, &first_solution)?;
    Ok((solution, first, second))
}

/// Every SE(2) or SE(3) pose in `values` by its key's index, in key order:
/// `[x, y, θ]` \[m, m, rad\] in 2D, `[x, y, z, qx, qy, qz, qw]` \[m\] in 3D
/// (g2o's order; other variable types are skipped).
pub fn poses(values: &Values) -> Vec<(u64, Vec<f64>)> {
    use tumble_solvers::sophus_lie::prelude::*;
    use tumble_solvers::sophus_lie::Isometry2F64;
    values
        .keys()
        .filter_map(|k| {
            if let Ok(p) = values.get::<Isometry3F64>(k) {
                let t = p.translation();
                let q = nalgebra::UnitQuaternion::from_matrix(&p.rotation().matrix());
                Some((k.index(), vec![t[0], t[1], t[2], q.i, q.j, q.k, q.w]))
            } else {
                values.get::<Isometry2F64>(k).ok().map(|p| {
                    let (t, r) = (p.translation(), p.rotation().matrix());
                    (k.index(), vec![t[0], t[1], r[(1, 0)].atan2(r[(0, 0)])])
                })
            }
        })
        .collect()
}

/// Positions seen from above, `(x, y)` \[m\], of every SE(2) or SE(3) pose in
/// `values`, in key order (other variable types are skipped).
pub fn top_view(values: &Values) -> Vec<(f64, f64)> {
    poses(values).into_iter().map(|(_, p)| (p[0], p[1])).collect()
}

/// Write a PNG (1000×800) of a pose graph seen from above: the initial guess
/// and the solution, each as the path through the poses in key order.
///
/// ```no_run
/// use tumble::io::g2o::{read_g2o, G2oOptions};
/// use tumble::solvers::{LmOptions, Optimizer};
/// let pg = read_g2o("M3500.g2o".as_ref(), &G2oOptions::default()).unwrap();
/// let (solved, _) = Optimizer::new(LmOptions::default()).optimize(&pg.graph, &pg.values).unwrap();
/// tumble::posegraph::plot_top_view(&pg.values, &solved, "M3500", "m3500.png".as_ref()).unwrap();
/// ```
pub fn plot_top_view(initial: &Values, solved: &Values, title: &str, path: &Path) -> Result<(), PlotError> {
    use crate::plot::{ScatterChart, Series};
    use plotters::style::RGBColor;
    let (a, b) = (top_view(initial), top_view(solved));
    if b.is_empty() {
        return Err(PlotError::Empty(path.to_path_buf()));
    }
    let chart = ScatterChart {
        title: title.to_string(),
        x_label: "x [m]".into(),
        y_label: "y [m]".into(),
        series: vec![
            Series { label: "initial guess".into(), color: RGBColor(200, 200, 200), points: a, line: true },
            Series { label: "solution".into(), color: RGBColor(31, 119, 180), points: b, line: true },
        ],
        equal_aspect: true,
        ..Default::default()
    };
    chart.write_png(path, 1000, 800)
}
