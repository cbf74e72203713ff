//! Several independently moving objects: segment the tracks ([`crate::segment`]), then
//! reconstruct each rigid group on its own with the single-object pipeline
//! ([`Reconstruction::from_tracks`]: its own set-aside, robust pass, camera choice,
//! completion, metric upgrade and refinement), cameras relative to that object.
//!
//! Objective: per object, the one of [`Reconstruction`]; the grouping, the energy of
//! [`crate::segment::segment`]. References: Costeira & Kanade, IJCV 1998 (multibody
//! factorization); Delong et al., IJCV 2012 (label costs).
//!
//! Complexity: the segmentation's, plus one single-object reconstruction per group, on
//! that group's tracks only (the groups partition the tracks, so the reconstructions
//! together cost about what one reconstruction of all tracks costs).

use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::Serialize;

use crate::segment::{Label, SegmentConfig, Segmentation, segment_table};
use crate::{Config, Id, Reconstruction, Result, TrackTable};

/// One object's result.
#[derive(Debug, Clone)]
pub struct ObjectResult {
    /// Index of the object (0 = the largest group, taken as the scene).
    pub index: usize,
    /// Input column indices of its tracks.
    pub tracks: Vec<usize>,
    /// Per-coordinate RMS of its tracks' fits to its affine subspace, px (for a group of
    /// several pieces, under the perspective fit that merged them).
    pub subspace_rms_px: f64,
    /// Groups of the affine segmentation it holds ([`crate::segment::ObjectGroup::pieces`]).
    pub pieces: usize,
    /// Its reconstruction, or why it failed (the other objects are still reconstructed).
    pub reconstruction: std::result::Result<Reconstruction, String>,
}

/// Segmentation plus one reconstruction per object.
#[derive(Debug, Clone)]
pub struct MultiBody {
    /// The segmentation (labels per input track, groups, σ, energy).
    pub segmentation: Segmentation,
    /// The objects, largest first.
    pub objects: Vec<ObjectResult>,
    /// Input track ids (for `objects.csv`).
    pub track_ids: Vec<Id>,
}

/// A serializable summary (`segmentation.json`).
#[derive(Debug, Clone, Serialize)]
pub struct MultiBodyReport {
    /// How the number of objects was set: `"auto"` or `"given"`.
    pub objects_mode: &'static str,
    /// Number of groups found.
    pub n_objects: usize,
    /// Which rule set that number: `"given"`, `"label_cost"`, `"eigengap"`,
    /// `"separation"`, `"perspective_merge"`, `"one_group_fallback"` (none found, one
    /// taken) or `"windows"` (a long sequence of short tracks segmented window by window;
    /// docs/math.md §11).
    pub count_rule: crate::segment::CountRule,
    /// The least separated pair of groups' median ratio of a track's RMS under the other
    /// group's subspace to that under its own; `null` with one group.
    pub separation: Option<f64>,
    /// The perspective-aware merge tests (pieces of one body seen in perspective joined;
    /// [`crate::segment::SegmentConfig::merge_ratio`]).
    pub merge_tests: Vec<crate::segment::MergeTest>,
    /// Tracks explained by no group.
    pub n_outlier_tracks: usize,
    /// Tracks seen in too few frames to be scored and not placed by the short-track step
    /// ([`crate::segment::Label::Unscored`]).
    pub n_unscored_tracks: usize,
    /// Of those, the tracks reconstructed with the only object when one was found (all of
    /// them then; 0 with several objects).
    pub n_unscored_in_the_only_object: usize,
    /// Per-coordinate RMS of all grouped tracks' subspace fits, px.
    pub sigma_px: f64,
    /// Final energy (χ² units).
    pub energy: f64,
    /// Label cost of one object defined on every frame (χ² units; 0 with a given count or
    /// windows).
    pub label_cost: f64,
    /// Hypotheses in the pool at the end.
    pub hypotheses: usize,
    /// Assign/refit rounds, and whether they stopped on their own.
    pub rounds: usize,
    pub converged: bool,
    pub seconds: f64,
    /// Per object.
    pub objects: Vec<ObjectReport>,
}

/// One object in [`MultiBodyReport`].
#[derive(Debug, Clone, Serialize)]
pub struct ObjectReport {
    pub index: usize,
    pub n_tracks: usize,
    /// Per-coordinate RMS of its tracks under its segmentation model, px (the affine
    /// subspace; for a group merged from `pieces` > 1, the perspective fit that merged it).
    pub subspace_rms_px: f64,
    /// Groups of the affine segmentation it holds (more than 1: merged by the
    /// perspective-aware test).
    pub pieces: usize,
    /// Sub-folder holding its reconstruction (`object_<index>`), when it succeeded.
    pub dir: Option<String>,
    /// Reprojection RMS of its reconstruction, px.
    pub rms_px: Option<f64>,
    /// The camera model its reconstruction used.
    pub camera: Option<crate::CameraModel>,
    /// Why its reconstruction failed.
    pub error: Option<String>,
}

impl MultiBody {
    /// Unscored tracks ([`Label::Unscored`]) reconstructed with the only object, when the
    /// segmentation found one (input column indices, increasing; empty otherwise): with one
    /// group there is no other group to tell them from, and the object's own robust pass
    /// judges them, as the single-object pipeline's does.
    pub fn unscored_in_the_only_object(&self) -> Vec<usize> {
        unscored_in_the_only_object(&self.segmentation)
    }

    /// The `segmentation.json` summary.
    pub fn report(&self, given: bool) -> MultiBodyReport {
        let s = &self.segmentation;
        MultiBodyReport {
            objects_mode: if given { "given" } else { "auto" },
            n_objects: self.objects.len(),
            count_rule: s.count_rule,
            separation: s.separation,
            merge_tests: s.merge_tests.clone(),
            n_outlier_tracks: s.n_outliers(),
            n_unscored_tracks: s.n_unscored(),
            n_unscored_in_the_only_object: self.unscored_in_the_only_object().len(),
            sigma_px: s.sigma,
            energy: s.energy,
            label_cost: s.label_cost,
            hypotheses: s.hypotheses,
            rounds: s.rounds,
            converged: s.converged,
            seconds: s.seconds,
            objects: self
                .objects
                .iter()
                .map(|o| ObjectReport {
                    index: o.index,
                    n_tracks: o.tracks.len(),
                    subspace_rms_px: o.subspace_rms_px,
                    pieces: o.pieces,
                    dir: o.reconstruction.as_ref().ok().map(|_| object_dir(o.index)),
                    rms_px: o.reconstruction.as_ref().ok().map(|r| r.rms_px),
                    camera: o.reconstruction.as_ref().ok().map(|r| r.camera_model),
                    error: o.reconstruction.as_ref().err().cloned(),
                })
                .collect(),
        }
    }

    /// `track,object` lines for every input track (`-1`: outlier, or unscored with several
    /// objects; an unscored track reconstructed with the only object is that object's).
    pub fn objects_csv(&self) -> String {
        let only = self.segmentation.objects.len() == 1;
        let mut s = String::from("track,object\n");
        for (id, l) in self.track_ids.iter().zip(&self.segmentation.labels) {
            let code = if only && *l == Label::Unscored {
                0
            } else {
                l.code()
            };
            s.push_str(&format!("{id},{code}\n"));
        }
        s
    }
}

/// Sub-folder name of object `k`'s reconstruction.
pub fn object_dir(k: usize) -> String {
    format!("object_{k}")
}

/// Segments `table`'s tracks and reconstructs each group with `config` (seeded by
/// `config.seed`). Errors: those of [`crate::segment::segment`] (bad configuration, too few tracks); a
/// group whose reconstruction fails is reported in its [`ObjectResult`] instead.
pub fn reconstruct_objects(
    table: &TrackTable,
    config: &Config,
    seg: &SegmentConfig,
) -> Result<MultiBody> {
    let mut rng = StdRng::seed_from_u64(config.seed);
    let segmentation = segment_table(table, seg, &mut rng)?;
    // Each object's tracks were just grouped: its pipeline does not segment them again
    // (its robust pass still searches for other objects among the tracks it rejects).
    let mut config = config.clone();
    if let Some(rc) = config.robust.as_mut() {
        rc.segment_first = false;
    }
    let config = &config;
    let all_frames: Vec<usize> = (0..table.n_frames()).collect();
    let unscored = unscored_in_the_only_object(&segmentation);
    let objects = segmentation
        .objects
        .iter()
        .enumerate()
        .map(|(k, g)| {
            let mut tracks = g.tracks.clone();
            if k == 0 && !unscored.is_empty() {
                tracks.extend_from_slice(&unscored);
                tracks.sort_unstable();
            }
            let sub = table.select(&all_frames, &tracks);
            ObjectResult {
                index: k,
                tracks,
                subspace_rms_px: g.rms,
                pieces: g.pieces,
                reconstruction: Reconstruction::from_tracks(&sub, config)
                    .map_err(|e| e.to_string()),
            }
        })
        .collect();
    Ok(MultiBody {
        segmentation,
        objects,
        track_ids: table.track_ids().to_vec(),
    })
}

/// [`MultiBody::unscored_in_the_only_object`] of `s`.
fn unscored_in_the_only_object(s: &Segmentation) -> Vec<usize> {
    if s.objects.len() != 1 {
        return Vec::new();
    }
    (0..s.labels.len())
        .filter(|&p| s.labels[p] == Label::Unscored)
        .collect()
}
