//! The Rust peers on the same problems: factrs, tiny-solver, apex-solver.

use crate::{median, peak_rss_mb, problem_name, skipped, Record};
use nalgebra as na;
use nalgebra034 as tna;
use std::path::Path;
use std::time::Instant;
use tumble_solvers::{se2, se3_from_quaternion, Graph, Values, X};

/// Cost of a peer's solution, evaluated by tumble's graph (½χ²), with the
/// vertices tumble holds constant left as they are.
fn chi2_of(graph: &Graph, template: &Values, poses: Vec<(u64, PoseOut)>) -> f64 {
    let mut v = template.clone();
    for (id, p) in poses {
        if v.is_constant(X(id)) {
            continue;
        }
        match p {
            PoseOut::Se2 { x, y, theta } => v.insert(X(id), se2(x, y, theta)),
            PoseOut::Se3 { q, t } => v.insert(X(id), se3_from_quaternion(q, t)),
        }
    }
    graph.chi2(&v).unwrap_or(f64::NAN)
}

/// A pose as a peer returns it.
pub enum PoseOut {
    /// Planar pose.
    Se2 {
        /// x \[m\].
        x: f64,
        /// y \[m\].
        y: f64,
        /// heading \[rad\].
        theta: f64,
    },
    /// Spatial pose: quaternion (w, x, y, z) and translation.
    Se3 {
        /// (w, x, y, z).
        q: [f64; 4],
        /// translation \[m\].
        t: na::Vector3<f64>,
    },
}

/// Vertices and edges of a g2o file, for the peers that need us to build their problem.
pub struct G2oData {
    /// (id, pose).
    pub vertices: Vec<(u64, PoseOut)>,
    /// (from, to, measurement, information in g2o order).
    pub edges: Vec<(u64, u64, PoseOut, na::DMatrix<f64>)>,
}

/// Minimal g2o parse for building peers' problems (tumble's reader has
/// already validated the file by the time this runs).
pub fn parse_g2o_data(path: &Path) -> Result<G2oData, tumble::InputError> {
    let text = std::fs::read_to_string(path).map_err(|e| tumble::InputError::file(path, e))?;
    parse_g2o_text(&text).map_err(|e| tumble::InputError::file(path, e))
}

fn parse_g2o_text(text: &str) -> Result<G2oData, String> {
    let mut vertices = Vec::new();
    let mut edges = Vec::new();
    for line in text.lines() {
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        let f = |i: usize| -> Result<f64, String> {
            t.get(i).and_then(|s| s.parse().ok()).ok_or_else(|| format!("bad line: {line}"))
        };
        let info = |start: usize, n: usize| -> Result<na::DMatrix<f64>, String> {
            let mut m = na::DMatrix::zeros(n, n);
            let mut k = start;
            for r in 0..n {
                for c in r..n {
                    m[(r, c)] = f(k)?;
                    m[(c, r)] = f(k)?;
                    k += 1;
                }
            }
            Ok(m)
        };
        match t[0] {
            "VERTEX_SE2" => vertices.push((f(1)? as u64, PoseOut::Se2 { x: f(2)?, y: f(3)?, theta: f(4)? })),
            "VERTEX_SE3:QUAT" => vertices.push((
                f(1)? as u64,
                PoseOut::Se3 { q: [f(8)?, f(5)?, f(6)?, f(7)?], t: na::Vector3::new(f(2)?, f(3)?, f(4)?) },
            )),
            "EDGE_SE2" => {
                edges.push((f(1)? as u64, f(2)? as u64, PoseOut::Se2 { x: f(3)?, y: f(4)?, theta: f(5)? }, info(6, 3)?))
            }
            "EDGE_SE3:QUAT" => edges.push((
                f(1)? as u64,
                f(2)? as u64,
                PoseOut::Se3 { q: [f(9)?, f(6)?, f(7)?, f(8)?], t: na::Vector3::new(f(3)?, f(4)?, f(5)?) },
                info(10, 6)?,
            )),
            _ => {}
        }
    }
    Ok(G2oData { vertices, edges })
}

fn finish(
    name: &str,
    solver: &str,
    graph: &Graph,
    values: &Values,
    times: &mut [f64],
    iterations: Option<usize>,
    poses: Vec<(u64, PoseOut)>,
) -> Record {
    let variables = values.keys().filter(|k| !values.is_constant(*k)).count();
    Record {
        problem: name.into(),
        solver: solver.into(),
        variables,
        factors: graph.len(),
        iterations,
        initial_chi2: graph.chi2(values).unwrap_or(f64::NAN),
        final_chi2: chi2_of(graph, values, poses),
        total_s: median(times),
        factorize_s: f64::NAN,
        peak_rss_mb: peak_rss_mb(),
        skipped: None,
    }
}

/// factrs 0.3 with its own g2o loader (which keeps the information matrices
/// and puts a prior on the first pose) and its Levenberg–Marquardt defaults.
pub fn run_factrs(path: &Path, repeat: usize) -> Record {
    use factrs::core::{LevenMarquardt, SE2, SE3};
    use factrs::traits::Optimizer as _;
    let name = problem_name(path);
    let Ok(tp) = crate::load(path, tumble::io::g2o::EdgeError::Log) else {
        return skipped(&name, "factrs", "tumble refuses this file");
    };
    if tp.is_bal {
        return skipped(&name, "factrs", "no bundle-adjustment reader");
    }
    let file = path.to_string_lossy().to_string();
    let mut times = Vec::new();
    let mut out = None;
    for _ in 0..repeat.max(1) {
        let (graph, init) = factrs::utils::load_g20(&file);
        let mut opt = LevenMarquardt::new(Default::default(), graph);
        let t = Instant::now();
        let r = opt.optimize(init);
        times.push(t.elapsed().as_secs_f64());
        out = Some(match r {
            Ok(v) => v,
            Err(factrs::optimizers::OptError::MaxIterations(v)) => v,
            Err(e) => return skipped(&name, "factrs", &format!("{e:?}")),
        });
    }
    let v = out.expect("ran");
    let ids: Vec<u64> = tp.values.keys().map(|k| k.index()).collect();
    let poses = ids
        .iter()
        .filter_map(|&id| {
            let key = factrs::utils::X(id as u32);
            if let Some(p) = v.get::<_, SE2>(key) {
                return Some((id, PoseOut::Se2 { x: p.x(), y: p.y(), theta: p.theta() }));
            }
            v.get::<_, SE3>(key).map(|p| {
                let r = p.rot();
                (
                    id,
                    PoseOut::Se3 {
                        q: [r.w(), r.x(), r.y(), r.z()],
                        t: na::Vector3::new(p.xyz()[0], p.xyz()[1], p.xyz()[2]),
                    },
                )
            })
        })
        .collect();
    finish(&name, "factrs", &tp.graph, &tp.values, &mut times, None, poses)
}

/// Whitened GTSAM between error for tiny-solver, written over its scalar type.
struct TinyBetween {
    se3: bool,
    /// Measurement: SE(2) (θ, x, y) or SE(3) quaternion (x, y, z, w) + t.
    z: Vec<f64>,
    /// Square-root information in tumble's tangent order (\[θ, x, y\] / \[ω, ν\]).
    w: na::DMatrix<f64>,
}

impl<T: tna::RealField> tiny_solver::factors::Factor<T> for TinyBetween {
    fn residual_func(&self, params: &[tna::DVector<T>]) -> tna::DVector<T> {
        use nalgebra034 as na;
        let c = |v: f64| T::from_f64(v).expect("f64 converts");
        let r: Vec<T> = if self.se3 {
            let iso = |p: &[T]| {
                let q = na::UnitQuaternion::from_quaternion(na::Quaternion::new(
                    p[3].clone(),
                    p[0].clone(),
                    p[1].clone(),
                    p[2].clone(),
                ));
                na::Isometry3::from_parts(na::Translation3::new(p[4].clone(), p[5].clone(), p[6].clone()), q)
            };
            let zc: Vec<T> = self.z.iter().map(|v| c(*v)).collect();
            let d = iso(&zc).inverse() * iso(params[0].as_slice()).inverse() * iso(params[1].as_slice());
            let w = d.rotation.scaled_axis();
            let th2 = w.norm_squared();
            let wx = w.cross_matrix();
            let coef = if th2.clone() < c(1e-10) {
                c(1.0 / 12.0)
            } else {
                let th = th2.clone().sqrt();
                T::one() / th2.clone() - (T::one() + th.clone().cos()) / (c(2.0) * th.clone() * th.sin())
            };
            let vinv = na::Matrix3::identity() - wx.clone() * c(0.5) + wx.clone() * wx * coef;
            let nu = vinv * d.translation.vector;
            vec![w[0].clone(), w[1].clone(), w[2].clone(), nu[0].clone(), nu[1].clone(), nu[2].clone()]
        } else {
            let iso = |th: T, x: T, y: T| na::Isometry2::new(na::Vector2::new(x, y), th);
            let p0 = &params[0];
            let p1 = &params[1];
            let d = iso(c(self.z[0]), c(self.z[1]), c(self.z[2])).inverse()
                * iso(p0[0].clone(), p0[1].clone(), p0[2].clone()).inverse()
                * iso(p1[0].clone(), p1[1].clone(), p1[2].clone());
            let th = d.rotation.angle();
            let (a, b) = if th.clone().abs() < c(1e-9) {
                (T::one(), th.clone() * c(0.5))
            } else {
                (th.clone().sin() / th.clone(), (T::one() - th.clone().cos()) / th.clone())
            };
            let det = a.clone() * a.clone() + b.clone() * b.clone();
            let t = d.translation.vector;
            let nx = (a.clone() * t[0].clone() + b.clone() * t[1].clone()) / det.clone();
            let ny = (-b * t[0].clone() + a * t[1].clone()) / det;
            vec![th, nx, ny]
        };
        let n = r.len();
        na::DVector::from_fn(n, |i, _| (0..n).fold(T::zero(), |acc, k| acc + c(self.w[(i, k)]) * r[k].clone()))
    }
}

/// Prior pinning a tiny-solver variable at its initial value.
struct TinyPrior {
    v: Vec<f64>,
}
impl<T: tna::RealField> tiny_solver::factors::Factor<T> for TinyPrior {
    fn residual_func(&self, params: &[tna::DVector<T>]) -> tna::DVector<T> {
        tna::DVector::from_fn(self.v.len(), |i, _| {
            (params[0][i].clone() - T::from_f64(self.v[i]).expect("f64")) * T::from_f64(1e3).expect("f64")
        })
    }
}

fn sqrt_info(info: &na::DMatrix<f64>, perm: &[usize]) -> Option<na::DMatrix<f64>> {
    let n = perm.len();
    let m = na::DMatrix::from_fn(n, n, |r, c| info[(perm[r], perm[c])]);
    na::Cholesky::new(m).map(|l| l.l().transpose())
}

/// tiny-solver 0.18: its own g2o loader drops the information matrices and adds
/// a Huber loss, so we build the problem ourselves with whitened residuals.
pub fn run_tiny(path: &Path, repeat: usize) -> Record {
    use tiny_solver::optimizer::Optimizer as _;
    let name = problem_name(path);
    let Ok(tp) = crate::load(path, tumble::io::g2o::EdgeError::Log) else {
        return skipped(&name, "tiny-solver", "tumble refuses this file");
    };
    if tp.is_bal {
        return skipped(&name, "tiny-solver", "no bundle-adjustment reader");
    }
    let data = match parse_g2o_data(path) {
        Ok(d) => d,
        Err(e) => return skipped(&name, "tiny-solver", &e.to_string()),
    };
    let mut problem = tiny_solver::Problem::new();
    let mut init = std::collections::HashMap::new();
    let key = |id: u64| format!("x{id}");
    let first = data.vertices.iter().map(|v| v.0).min().unwrap_or(0);
    for (id, p) in &data.vertices {
        match p {
            PoseOut::Se2 { x, y, theta } => {
                init.insert(key(*id), tna::DVector::from_vec(vec![*theta, *x, *y]));
            }
            PoseOut::Se3 { q, t } => {
                init.insert(key(*id), tna::DVector::from_vec(vec![q[1], q[2], q[3], q[0], t[0], t[1], t[2]]));
                problem.set_variable_manifold(&key(*id), std::sync::Arc::new(tiny_solver::manifold::se3::SE3Manifold));
            }
        }
        if *id == first {
            let dim = if matches!(p, PoseOut::Se2 { .. }) { 3 } else { 6 };
            let v = init[&key(*id)].as_slice().to_vec();
            let _ = dim;
            let n = v.len();
            problem.add_residual_block(n, &[&key(*id)], Box::new(TinyPrior { v }), None);
        }
    }
    for (a, b, z, info) in &data.edges {
        let (se3, zv, perm): (bool, Vec<f64>, &[usize]) = match z {
            PoseOut::Se2 { x, y, theta } => (false, vec![*theta, *x, *y], &[2, 0, 1]),
            PoseOut::Se3 { q, t } => (true, vec![q[1], q[2], q[3], q[0], t[0], t[1], t[2]], &[3, 4, 5, 0, 1, 2]),
        };
        let Some(w) = sqrt_info(info, perm) else {
            return skipped(&name, "tiny-solver", "information not positive definite");
        };
        let dim = w.nrows();
        problem.add_residual_block(dim, &[&key(*a), &key(*b)], Box::new(TinyBetween { se3, z: zv, w }), None);
    }
    let mut times = Vec::new();
    let mut out = None;
    for _ in 0..repeat.max(1) {
        let opt = tiny_solver::LevenbergMarquardtOptimizer::default();
        let t = Instant::now();
        let r = opt.optimize(&problem, &init, None);
        times.push(t.elapsed().as_secs_f64());
        out = r;
    }
    let Some(v) = out else { return skipped(&name, "tiny-solver", "optimizer returned no solution") };
    let poses = data
        .vertices
        .iter()
        .filter_map(|(id, p)| {
            let s = v.get(&key(*id))?;
            Some(match p {
                PoseOut::Se2 { .. } => (*id, PoseOut::Se2 { theta: s[0], x: s[1], y: s[2] }),
                PoseOut::Se3 { .. } => {
                    (*id, PoseOut::Se3 { q: [s[3], s[0], s[1], s[2]], t: na::Vector3::new(s[4], s[5], s[6]) })
                }
            })
        })
        .collect();
    finish(&name, "tiny-solver", &tp.graph, &tp.values, &mut times, None, poses)
}

/// apex-solver 1.5 with its own g2o loader, information matrices as noise
/// models, a prior on the first pose and its Levenberg–Marquardt defaults.
pub fn run_apex(path: &Path, repeat: usize) -> Record {
    use apex_solver::apex_io::{G2oLoader, GraphLoader};
    use apex_solver::apex_manifolds::ManifoldType;
    use apex_solver::core::noise::NoiseModel as ApexNoise;
    use apex_solver::core::problem::Problem;
    use apex_solver::factors::pose::{BetweenFactor, PriorFactor};
    use apex_solver::optimizer::LevenbergMarquardt;
    use apex_solver::JacobianMode;
    let name = problem_name(path);
    let Ok(tp) = crate::load(path, tumble::io::g2o::EdgeError::Log) else {
        return skipped(&name, "apex-solver", "tumble refuses this file");
    };
    if tp.is_bal {
        return skipped(&name, "apex-solver", "not wired up for bundle adjustment here");
    }
    let graph = match G2oLoader::load(path) {
        Ok(g) => g,
        Err(e) => return skipped(&name, "apex-solver", &format!("{e}")),
    };
    let mut times = Vec::new();
    let mut iterations = 0;
    let mut poses = Vec::new();
    for _ in 0..repeat.max(1) {
        let mut problem = Problem::new(JacobianMode::Sparse);
        let mut keys = std::collections::HashMap::new();
        let mut ids: Vec<usize> = graph.vertices_se2.keys().chain(graph.vertices_se3.keys()).copied().collect();
        ids.sort();
        for &id in &ids {
            if let Some(v) = graph.vertices_se2.get(&id) {
                keys.insert(
                    id,
                    problem.add_variable(ManifoldType::SE2, na::dvector![v.pose.x(), v.pose.y(), v.pose.angle()]),
                );
            } else if let Some(v) = graph.vertices_se3.get(&id) {
                let q = v.pose.rotation_quaternion();
                let t = v.pose.translation();
                keys.insert(
                    id,
                    problem.add_variable(ManifoldType::SE3, na::dvector![t.x, t.y, t.z, q.w, q.i, q.j, q.k]),
                );
            }
        }
        let first = ids[0];
        let prior_noise = |n: usize| ApexNoise::from_sigmas(&vec![1e-3; n]).expect("positive sigmas");
        if let Some(v) = graph.vertices_se2.get(&first) {
            problem.add_residual_block_with_noise(
                &[keys[&first]],
                Box::new(PriorFactor::new(v.pose.clone())),
                None,
                prior_noise(3),
            );
        }
        if let Some(v) = graph.vertices_se3.get(&first) {
            problem.add_residual_block_with_noise(
                &[keys[&first]],
                Box::new(PriorFactor::new(v.pose.clone())),
                None,
                prior_noise(6),
            );
        }
        let edges_se2 = graph.edges_se2.iter().map(|e| (e.from, e.to, e.information.as_slice(), 3));
        let edges_se3 = graph.edges_se3.iter().map(|e| (e.from, e.to, e.information.as_slice(), 6));
        let factors: Vec<Box<dyn apex_solver::factors::Factor + Send + Sync>> = graph
            .edges_se2
            .iter()
            .map(|e| {
                Box::new(BetweenFactor::new(e.measurement.clone()))
                    as Box<dyn apex_solver::factors::Factor + Send + Sync>
            })
            .chain(graph.edges_se3.iter().map(|e| Box::new(BetweenFactor::new(e.measurement.clone())) as _))
            .collect();
        for ((from, to, info, n), factor) in edges_se2.chain(edges_se3).zip(factors) {
            let Ok(noise) = ApexNoise::from_information(na::DMatrix::from_column_slice(n, n, info)) else {
                return skipped(&name, "apex-solver", "information not positive definite");
            };
            problem.add_residual_block_with_noise(&[keys[&from], keys[&to]], factor, None, noise);
        }
        let mut solver = LevenbergMarquardt::new();
        let t = Instant::now();
        let r = solver.optimize(&mut problem);
        times.push(t.elapsed().as_secs_f64());
        let r = match r {
            Ok(r) => r,
            Err(e) => return skipped(&name, "apex-solver", &format!("{e}")),
        };
        iterations = r.iterations;
        poses = ids
            .iter()
            .filter_map(|id| {
                let p = r.parameters.get(keys[id])?.as_param_slice().to_vec();
                Some(if p.len() == 3 {
                    (*id as u64, PoseOut::Se2 { x: p[0], y: p[1], theta: p[2] })
                } else {
                    (*id as u64, PoseOut::Se3 { q: [p[3], p[4], p[5], p[6]], t: na::Vector3::new(p[0], p[1], p[2]) })
                })
            })
            .collect();
    }
    finish(&name, "apex-solver", &tp.graph, &tp.values, &mut times, Some(iterations), poses)
}
