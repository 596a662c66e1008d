//! The clusters of the rig's cluster-robust ("sandwich") covariances: which
//! factors' errors may be alike (those of neighbouring frames, those of one
//! target corner), and the covariances regrouped from one linearization.

use super::RigInput;
use std::collections::BTreeSet;
use tumble_solvers::{Covariances, RobustCovariances};

/// The fine clusters of the cluster-robust covariance: one per frame and
/// target corner (that corner's factors in that frame, every camera's), and
/// one per frame for the IMU link and bias walk that start there; the
/// target's gauge is a cluster of its own. Grouped afterwards by blocks of
/// frames or by corner ([`robust_partitions`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct ClusterLabels {
    /// Labels per frame: every corner id, then the frame's motion.
    stride: usize,
}

impl ClusterLabels {
    /// The labels for `input`'s corners: room for every corner id it holds.
    pub(super) fn of(input: &RigInput) -> ClusterLabels {
        let ids = input.cameras.iter().flat_map(|c| &c.views).flat_map(|v| &v.corners).map(|c| c.id);
        ClusterLabels { stride: ids.max().map_or(0, |m| m + 1) + 1 }
    }

    /// Corner `id` seen in frame `frame`.
    pub(super) fn corner(self, frame: usize, id: usize) -> usize {
        frame * self.stride + id
    }

    /// The IMU's link and bias walk from frame `frame`.
    pub(super) fn motion(self, frame: usize) -> usize {
        frame * self.stride + self.stride - 1
    }

    fn frame(self, label: usize) -> usize {
        label / self.stride
    }

    /// The cluster of `label` when grouped by corner: the corner's id, or
    /// (the IMU's factors, independent between frames) one past every id per frame.
    fn by_corner(self, label: usize) -> usize {
        match label % self.stride {
            id if id + 1 < self.stride => id,
            _ => self.stride + self.frame(label),
        }
    }
}

/// Blocks of the coarse partition of the cluster-robust covariance.
///
/// Batch means over blocks of √N frames are the most precise when the
/// corners' errors are correlated over less than a block; errors that follow
/// the hand's motion (the same view geometry for seconds, an IMU error the
/// model lacks) stay alike for longer and make them too small. A fixed,
/// small number of blocks is right whatever the correlation's length, at the
/// price of a noisier σ (Ibragimov & Müller 2010, "t-statistic based
/// correlation and heterogeneity robust inference", study 4–16 groups).
pub const COARSE_BLOCKS: usize = 8;

/// The cluster-robust covariances over blocks of ⌊√N⌋ consecutive frames,
/// over [`COARSE_BLOCKS`] blocks (when those are longer) and over the
/// target's corners, from the fine clusters `labels` made, with the number
/// of corners.
///
/// The corners' clusters hold when a corner's error is alike in every view
/// that sees it: a target printed or mounted imperfectly (a square's edge
/// off by a tenth of a millimetre, a board not flat), or a detector whose
/// bias depends on where in the image, through which part of the lens, a
/// corner is usually seen. Such errors are common to every block of frames
/// — to both halves of the recording too — so neither the blocks nor a
/// split shows them (OpenCV's `calibrateCameraRO` estimates them as
/// per-corner offsets instead).
pub(super) fn robust_partitions(
    cov: &RobustCovariances,
    labels: ClusterLabels,
    frames: usize,
) -> (Vec<super::BlockPartition>, usize, Vec<Covariances>) {
    let fine = ((frames as f64).sqrt().floor() as usize).max(1);
    let coarse = frames.div_ceil(COARSE_BLOCKS);
    let mut partitions = Vec::new();
    let mut covs = Vec::new();
    for block_frames in std::iter::once(fine).chain((coarse > fine).then_some(coarse)) {
        let (c, _) = cov.regrouped(|label| labels.frame(label) / block_frames);
        partitions.push(super::BlockPartition { block_frames, blocks: frames.div_ceil(block_frames) });
        covs.push(c);
    }
    let (c, _) = cov.regrouped(|label| labels.by_corner(label));
    let corners: BTreeSet<usize> = cov
        .influences
        .iter()
        .filter_map(|(l, _)| *l)
        .map(|l| labels.by_corner(l))
        .filter(|&c| c < labels.stride)
        .collect();
    covs.push(c);
    (partitions, corners.len(), covs)
}
