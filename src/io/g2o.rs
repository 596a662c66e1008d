//! g2o pose-graph files: `VERTEX_SE2`/`EDGE_SE2` and `VERTEX_SE3:QUAT`/`EDGE_SE3:QUAT`
//! with their information matrices, plus `FIX`.
//!
//! Conventions: SE(2) tangents in tumble are `[θ, x, y]` and SE(3) `[ω, ν]`, so
//! g2o's information matrices (ordered `[x, y, θ]` and `[x, y, z, qx, qy, qz]`)
//! are permuted, not rescaled, exactly as GTSAM's `readG2o` does. The error of
//! each edge is GTSAM's `BetweenFactor`: `Log(Z⁻¹ X₁⁻¹ X₂)`, or for 3-D edges
//! optionally Ceres' `pose_graph_3d` error ([`EdgeError`]).

use crate::error::InputError;
use crate::io::tokens::{read_text, LineTokens};
use nalgebra::{DMatrix, Vector3};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;
use tumble_factors::pose_graph_3d::QuaternionPoseError;
use tumble_factors::BetweenFactor;
use tumble_solvers::{se2, se3_from_quaternion, DynVariable, Graph, Key, NoiseModel, Values, X};

/// What to do with an information matrix that is not positive definite.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BadInformation {
    /// Refuse the file (the default).
    #[default]
    Refuse,
    /// Replace it by the nearest positive-definite matrix (eigenvalues clamped
    /// to 1e-9 · the largest) and report every such edge as a warning.
    Repair,
}

/// The error each `EDGE_SE3:QUAT` edge contributes (a planar file with
/// anything but [`EdgeError::Log`] is refused).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum EdgeError {
    /// GTSAM's `BetweenFactor`, `Log(Z⁻¹ X₁⁻¹ X₂)` (the default; GTSAM, factrs,
    /// tiny-solver and apex-solver minimize this cost).
    #[default]
    Log,
    /// Ceres' `pose_graph_3d` example error `[R₁ᵀ(p₂−p₁) − p_z, 2·vec(q_z q₁₂⁻¹)]`
    /// ([`tumble_factors::pose_graph_3d::QuaternionPoseError`]), to compare minima with Ceres.
    CeresQuaternion,
}

/// Options of [`read_g2o`].
#[derive(Clone, Debug, Default)]
pub struct G2oOptions {
    /// Handling of non-positive-definite information matrices.
    pub bad_information: BadInformation,
    /// The cost of a 3-D edge.
    pub edge_error: EdgeError,
}

/// Dimension of a pose graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseKind {
    /// Planar poses.
    Se2,
    /// Spatial poses.
    Se3,
}

/// A pose graph read from a g2o file.
pub struct PoseGraph {
    /// One `BetweenFactor` per edge.
    pub graph: Graph,
    /// Initial poses, keyed `X(vertex id)`. Vertices named by `FIX` (or, when
    /// none is, the lowest id) are held constant to fix the gauge.
    pub values: Values,
    /// SE(2) or SE(3).
    pub kind: PoseKind,
    /// Number of vertices.
    pub vertices: usize,
    /// Number of edges.
    pub edges: usize,
    /// Warnings (e.g. repaired information matrices).
    pub warnings: Vec<String>,
}

fn information(
    file: &Path,
    line: usize,
    upper: &[f64],
    n: usize,
    perm: &[usize],
    opts: &G2oOptions,
    warnings: &mut Vec<String>,
) -> Result<NoiseModel, InputError> {
    let mut g = DMatrix::zeros(n, n);
    let mut k = 0;
    for r in 0..n {
        for c in r..n {
            g[(r, c)] = upper[k];
            g[(c, r)] = upper[k];
            k += 1;
        }
    }
    let m = DMatrix::from_fn(n, n, |r, c| g[(perm[r], perm[c])]);
    match NoiseModel::from_information(&m) {
        Ok(noise) => Ok(noise),
        Err(_) => {
            let eig = nalgebra::SymmetricEigen::new(m.clone());
            let min = eig.eigenvalues.min();
            match opts.bad_information {
                BadInformation::Refuse => Err(InputError::at(
                    file,
                    line,
                    format!("information matrix is not positive definite (smallest eigenvalue {min:.3e})"),
                )
                .with_hint("use --repair-information to replace such matrices by the nearest positive-definite one")),
                BadInformation::Repair => {
                    let max = eig.eigenvalues.max().max(1.0);
                    let clamped = eig.eigenvalues.map(|l| l.max(1e-9 * max));
                    let fixed = &eig.eigenvectors * DMatrix::from_diagonal(&clamped) * eig.eigenvectors.transpose();
                    warnings.push(format!(
                        "{}:{}: information matrix not positive definite (smallest eigenvalue {min:.3e}); repaired",
                        file.display(),
                        line
                    ));
                    NoiseModel::from_information(&((&fixed + fixed.transpose()) * 0.5))
                        .map_err(|e| InputError::at(file, line, format!("information matrix cannot be repaired: {e}")))
                }
            }
        }
    }
}

/// Read a g2o pose graph.
///
/// ```no_run
/// let pg = tumble::io::g2o::read_g2o("M3500.g2o".as_ref(), &Default::default()).unwrap();
/// println!("{} poses, {} edges", pg.vertices, pg.edges);
/// ```
pub fn read_g2o(path: &Path, opts: &G2oOptions) -> Result<PoseGraph, InputError> {
    parse_g2o(path, &read_text(path)?, opts)
}

/// Parse g2o text; `path` is only used in messages.
pub fn parse_g2o(path: &Path, text: &str, opts: &G2oOptions) -> Result<PoseGraph, InputError> {
    let mut r = G2oReader {
        path,
        opts,
        kind: None,
        values: Values::new(),
        vertex_lines: BTreeMap::new(),
        edges: Vec::new(),
        fixed: Vec::new(),
        warnings: Vec::new(),
    };
    for (i, raw) in text.lines().enumerate() {
        let l = raw.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let tag = l.split_whitespace().next().unwrap_or("");
        r.element(tag, LineTokens::new(path, i + 1, &l[tag.len()..]), i + 1)?;
    }
    r.finish()
}

/// An edge as read: its line, the vertices it joins, its measurement and noise.
type EdgeRead = (usize, u64, u64, EdgeMeas, NoiseModel);

/// What a g2o file has given so far.
struct G2oReader<'a> {
    path: &'a Path,
    opts: &'a G2oOptions,
    kind: Option<PoseKind>,
    values: Values,
    /// Each vertex's line.
    vertex_lines: BTreeMap<u64, usize>,
    edges: Vec<EdgeRead>,
    /// `FIX` lines: line and vertex.
    fixed: Vec<(usize, u64)>,
    warnings: Vec<String>,
}

impl G2oReader<'_> {
    fn set_kind(&mut self, k: PoseKind, line: usize) -> Result<(), InputError> {
        match self.kind {
            Some(old) if old != k => Err(InputError::at(self.path, line, "file mixes SE(2) and SE(3) elements")),
            _ => {
                self.kind = Some(k);
                Ok(())
            }
        }
    }

    fn vertex(&mut self, id: u64, ln: usize) -> Result<(), InputError> {
        if self.vertex_lines.insert(id, ln).is_some() {
            return Err(InputError::at(self.path, ln, format!("vertex {id} defined twice")));
        }
        Ok(())
    }

    /// A unit quaternion `(qx, qy, qz, qw)` read from `t`, refused off the unit sphere.
    fn quaternion(&self, t: &mut LineTokens, ln: usize) -> Result<[f64; 4], InputError> {
        let (qx, qy, qz, qw) = (t.f64("qx")?, t.f64("qy")?, t.f64("qz")?, t.f64("qw")?);
        let qn = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
        if (qn - 1.0).abs() > 1e-3 {
            return Err(InputError::at(self.path, ln, format!("quaternion norm is {qn}, not 1")));
        }
        Ok([qw, qx, qy, qz])
    }

    /// One element (line `ln`, its tag and the tokens after it).
    fn element(&mut self, tag: &str, mut t: LineTokens, ln: usize) -> Result<(), InputError> {
        let (path, opts) = (self.path, self.opts);
        match tag {
            "VERTEX_SE2" => {
                self.set_kind(PoseKind::Se2, ln)?;
                let id = t.usize("vertex id")? as u64;
                let (x, y, th) = (t.f64("x")?, t.f64("y")?, t.f64("theta")?);
                t.finish()?;
                self.vertex(id, ln)?;
                self.values.insert(X(id), se2(x, y, th));
            }
            "VERTEX_SE3:QUAT" => {
                self.set_kind(PoseKind::Se3, ln)?;
                let id = t.usize("vertex id")? as u64;
                let p = Vector3::new(t.f64("x")?, t.f64("y")?, t.f64("z")?);
                let q = self.quaternion(&mut t, ln)?;
                t.finish()?;
                self.vertex(id, ln)?;
                self.values.insert(X(id), se3_from_quaternion(q, p));
            }
            "EDGE_SE2" => {
                self.set_kind(PoseKind::Se2, ln)?;
                let (a, b) = (t.usize("from id")? as u64, t.usize("to id")? as u64);
                let (x, y, th) = (t.f64("dx")?, t.f64("dy")?, t.f64("dtheta")?);
                let info: Vec<f64> =
                    (0..6).map(|k| t.f64(&format!("information entry {}", k + 1))).collect::<Result<_, _>>()?;
                t.finish()?;
                let noise = information(path, ln, &info, 3, &[2, 0, 1], opts, &mut self.warnings)?;
                self.edges.push((ln, a, b, EdgeMeas::Se2(se2(x, y, th)), noise));
            }
            "EDGE_SE3:QUAT" => {
                self.set_kind(PoseKind::Se3, ln)?;
                let (a, b) = (t.usize("from id")? as u64, t.usize("to id")? as u64);
                let p = Vector3::new(t.f64("x")?, t.f64("y")?, t.f64("z")?);
                let q = self.quaternion(&mut t, ln)?;
                let info: Vec<f64> =
                    (0..21).map(|k| t.f64(&format!("information entry {}", k + 1))).collect::<Result<_, _>>()?;
                t.finish()?;
                // Ceres' error is ordered as g2o's matrix, [position, rotation].
                let perm: &[usize] =
                    if opts.edge_error == EdgeError::Log { &[3, 4, 5, 0, 1, 2] } else { &[0, 1, 2, 3, 4, 5] };
                let noise = information(path, ln, &info, 6, perm, opts, &mut self.warnings)?;
                self.edges.push((ln, a, b, EdgeMeas::Se3(se3_from_quaternion(q, p)), noise));
            }
            "FIX" => {
                let id = t.usize("vertex id")? as u64;
                t.finish()?;
                self.fixed.push((ln, id));
            }
            other => {
                return Err(InputError::at(path, ln, format!("unknown tag '{other}'"))
                    .with_hint("supported: VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX"))
            }
        }
        Ok(())
    }

    /// The graph of the edges read, with the fixed vertices (the first when
    /// none is) held constant.
    fn finish(mut self) -> Result<PoseGraph, InputError> {
        let (path, opts) = (self.path, self.opts);
        let kind = self
            .kind
            .ok_or_else(|| InputError::file(path, "no vertex or edge found").with_hint("is this a g2o file?"))?;
        if kind == PoseKind::Se2 && opts.edge_error != EdgeError::Log {
            return Err(InputError::file(
                path,
                "Ceres' quaternion edge error applies to 3-D pose graphs; this one is planar",
            ));
        }
        let posed = self.chain_missing_vertices()?;
        let mut graph = Graph::new();
        let n_edges = self.edges.len();
        for (ln, a, b, meas, noise) in self.edges {
            if a == b {
                return Err(InputError::at(path, ln, format!("edge connects vertex {a} to itself")));
            }
            match meas {
                EdgeMeas::Se2(z) => graph.add(BetweenFactor::new(X(a), X(b), z), noise),
                EdgeMeas::Se3(z) => match opts.edge_error {
                    EdgeError::Log => graph.add(BetweenFactor::new(X(a), X(b), z), noise),
                    EdgeError::CeresQuaternion => graph.add(QuaternionPoseError::new(X(a), X(b), &z), noise),
                },
            };
        }
        if self.fixed.is_empty() {
            if let Some(&id) = posed.iter().next() {
                self.values.set_constant(X(id), true);
            }
        }
        for (ln, id) in self.fixed {
            if !posed.contains(&id) {
                return Err(InputError::at(path, ln, format!("FIX names vertex {id}, which is not defined")));
            }
            self.values.set_constant(X(id), true);
        }
        if n_edges == 0 {
            return Err(InputError::file(path, "has no edges: a pose graph without measurements has nothing to solve"));
        }
        let vertices = posed.len();
        Ok(PoseGraph { graph, values: self.values, kind, vertices, edges: n_edges, warnings: self.warnings })
    }
}

impl G2oReader<'_> {
    /// Initial poses of the vertices no `VERTEX` line gave (files of edges
    /// alone are common): chained along the edges, breadth-first from the
    /// vertices that have one — from the lowest id, at the origin, when none
    /// has — as g2o's odometry guess does. Returns every posed vertex; a
    /// warning says how many were chained.
    fn chain_missing_vertices(&mut self) -> Result<BTreeSet<u64>, InputError> {
        let mut posed: BTreeSet<u64> = self.vertex_lines.keys().copied().collect();
        if self.edges.iter().flat_map(|e| [e.1, e.2]).all(|id| posed.contains(&id)) {
            return Ok(posed);
        }
        let mut touching: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
        for (k, e) in self.edges.iter().enumerate() {
            touching.entry(e.1).or_default().push(k);
            touching.entry(e.2).or_default().push(k);
        }
        let root = *touching.keys().next().expect("an edge was read");
        let mut queue: VecDeque<u64> = posed.iter().copied().collect();
        if queue.is_empty() {
            match self.edges[0].3 {
                EdgeMeas::Se2(_) => self.values.insert(X(root), se2(0.0, 0.0, 0.0)),
                EdgeMeas::Se3(_) => {
                    self.values.insert(X(root), se3_from_quaternion([1.0, 0.0, 0.0, 0.0], Vector3::zeros()))
                }
            }
            posed.insert(root);
            queue.push_back(root);
        }
        let mut chained = 0;
        while let Some(v) = queue.pop_front() {
            for &k in touching.get(&v).map(Vec::as_slice).unwrap_or_default() {
                let (_, a, b, meas, _) = &self.edges[k];
                let (other, forward) = if *a == v { (*b, true) } else { (*a, false) };
                if posed.contains(&other) {
                    continue;
                }
                let pose = meas.chain(&self.values, X(v), forward).map_err(|e| InputError::file(self.path, e))?;
                self.values.insert_dyn(X(other), pose);
                posed.insert(other);
                queue.push_back(other);
                chained += 1;
            }
        }
        if let Some((ln, id)) =
            self.edges.iter().flat_map(|e| [(e.0, e.1), (e.0, e.2)]).find(|(_, id)| !posed.contains(id))
        {
            return Err(InputError::at(
                self.path,
                ln,
                format!("vertex {id} has no VERTEX line, and no chain of edges links it to a vertex that has one"),
            ));
        }
        self.warnings.push(format!(
            "{}: {chained} vertices without a VERTEX line: their initial poses chained along the edges (breadth-first from {})",
            self.path.display(),
            if self.vertex_lines.is_empty() { format!("vertex {root} at the origin") } else { "the vertices given".into() }
        ));
        Ok(posed)
    }
}

enum EdgeMeas {
    Se2(tumble_solvers::sophus_lie::Isometry2F64),
    Se3(tumble_solvers::sophus_lie::Isometry3F64),
}

impl EdgeMeas {
    /// The pose of an edge's other vertex from the pose of `from` (the edge's
    /// first vertex when `forward`, else its second): `T_from · Z` or `T_from · Z⁻¹`.
    fn chain(&self, values: &Values, from: Key, forward: bool) -> Result<Box<dyn DynVariable>, String> {
        let err = |e: tumble_solvers::ValueError| e.to_string();
        Ok(match self {
            EdgeMeas::Se2(z) => {
                let t = values.get::<tumble_solvers::sophus_lie::Isometry2F64>(from).map_err(err)?;
                Box::new(t.group_mul(if forward { *z } else { z.inverse() }))
            }
            EdgeMeas::Se3(z) => {
                let t = values.get::<tumble_solvers::sophus_lie::Isometry3F64>(from).map_err(err)?;
                Box::new(t.group_mul(if forward { *z } else { z.inverse() }))
            }
        })
    }
}
