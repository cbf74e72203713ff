//! Long sequences of short tracks, segmented window by window.
//!
//! Over a long video whose tracks each last a short part of it, one affine subspace per
//! body defined on every frame is what [`super::segment`] looks for, but its hypotheses
//! are local — a few neighbouring tracks, grown to the tracks they explain over the frames
//! they are defined on — and the refits that would carry them along the sequence (ALS over
//! a chain of overlapping tracks) converge slowly. Measured (docs/results.md): 120 frames
//! of tracks lasting 60 are segmented with 0.3 % error, 600 frames of the same tracks with
//! 42 % (three mixed groups for two bodies).
//!
//! # Method
//!
//! 1. **Windows**: length `L = 2ℓ` frames (`ℓ` the median number of frames of the tracks
//!    seen in enough frames to be scored; at least `4 · min_overlap`), consecutive windows
//!    overlapping by `L/2`. Used when the sequence is at least `3L` frames long and the
//!    number of objects is found ([`super::Objects::Auto`]); shorter sequences, whose tracks
//!    span a good part of the frames, are segmented whole.
//! 2. Each window is **segmented on its own** ([`super::segment`]'s steps 1–7 on the
//!    window's frames and the tracks seen in at least 3 of them).
//! 3. **Links**: group `g` of window `k` and group `h` of window `k + 1` are one object
//!    when each is the other's best match by the number of tracks labelled `g` in `k` and
//!    `h` in `k + 1` (the tracks crossing the overlap), and those tracks are at least 3 and
//!    a quarter of the smaller of the two groups' tracks scored in both windows. A group
//!    without a link is matched the same way to a group of window `k − 1` that no group of
//!    `k` continued (across one window that held two bodies in one group), else starts a
//!    new object. Mutual best matches keep a window where two bodies could not be told
//!    apart from joining their chains.
//! 4. **Labels**: each track takes its windows' majority (an object, or outlier); ties go
//!    to the window whose centre is nearest the track's middle frame. Objects with fewer
//!    than `min_group_tracks` tracks are dissolved into outliers.
//! 5. **Each object's subspace on every frame**: its window pieces' subspaces chained into
//!    the first piece's affine frame — consecutive pieces related by the affine map
//!    `s ↦ A s + b` between their shared tracks' coordinates (least squares), a piece's
//!    cameras `M A⁻¹`, offsets `t − M A⁻¹ b` — then refitted to its tracks by ALS (the
//!    refit kept unless it loses frames the chain defined).
//! 6. **Broken chains merged**: while two objects' separation (the median over their
//!    tracks of `r_other / r_own` under these subspaces) is below
//!    [`SegmentConfig::window_merge_separation`], they are one body whose chain broke
//!    (a window that split it), and merge. The objects' RMS, noise and separation are
//!    measured under the final subspaces.
//!
//! # Complexity
//!
//! `W ≈ 2F/L` windows, each one segmentation of the tracks it sees (about `2/W` of the
//! observations each, so the windows together cost about twice one segmentation of a
//! table with the window's density, times `W/2`): linear in the frames at a fixed track
//! length and density. Choosing each window's tracks `O(W · N log k)` (a binary search in
//! every track's frames per window); links `O(Σ_k n_k)`; labels `O(n_obs)`; the stitching
//! one ALS refit per object. Memory: one window's segmentation at a time (its estimator
//! cut from the whole one's, [`TrackSubspace::select`]), plus the labels of every window
//! (about 2–3 per track), beside the estimator over all tracks (for the windows' plan, the
//! stitching and the scores), which holds the observations per track: `O(n_obs)` from a
//! sparse table ([`super::segment_table`]), with no `2F × N` matrix.

use std::time::Instant;

use nalgebra::{Matrix3, Matrix4, Vector4};
use rand::Rng;

use super::{
    CountRule, Label, ObjectGroup, Objects, SegmentConfig, Segmentation, least_separation,
    segment_tracks,
};
use crate::robust::subspace::{AffineSubspace, TrackSubspace};
use crate::{Error, Result};

/// Every track's `(ν_p r²_p, ν_p)` under one subspace (`None`: not scorable).
type Chi = Vec<Option<(f64, f64)>>;

/// The windows `[a, b)` of a long sequence, or `None` to segment it whole (see the module
/// documentation, step 1).
pub(super) fn plan(ts: &TrackSubspace, cfg: &SegmentConfig) -> Option<Vec<(usize, usize)>> {
    if !cfg.windows || !matches!(cfg.objects, Objects::Auto) {
        return None;
    }
    let f = ts.n_frames();
    let mut lens: Vec<usize> = (0..ts.n_tracks())
        .map(|p| ts.frames_of(p).len())
        .filter(|&k| k >= ts.min_overlap())
        .collect();
    if lens.is_empty() {
        return None;
    }
    let mid = lens.len() / 2;
    let median = *lens.select_nth_unstable(mid).1;
    let len = (2 * median).max(4 * ts.min_overlap());
    if f < 3 * len {
        return None;
    }
    let step = len / 2;
    let mut windows = Vec::new();
    let mut a = 0;
    loop {
        let b = (a + len).min(f);
        // The last window is a full one, ending at the last frame.
        windows.push((b.saturating_sub(len), b));
        if b == f {
            break;
        }
        a += step;
    }
    Some(windows)
}

/// One window's group: its tracks (input indices, sorted) and its subspace on the input's
/// frames (defined on the window's only).
struct Piece {
    tracks: Vec<usize>,
    model: AffineSubspace,
    pieces: usize,
}

/// [`super::segment`] of a long sequence, window by window (see the module documentation).
pub(super) fn segment_windows<R: Rng + ?Sized>(
    ts: &TrackSubspace,
    windows: &[(usize, usize)],
    cfg: &SegmentConfig,
    rng: &mut R,
    t0: Instant,
) -> Result<Segmentation> {
    let (nf, n) = (ts.n_frames(), ts.n_tracks());
    // Per window: each track it saw and its label there (sorted by track), and its groups.
    let mut labels_in: Vec<Vec<(usize, Label)>> = Vec::with_capacity(windows.len());
    let mut groups_in: Vec<Vec<Piece>> = Vec::with_capacity(windows.len());
    let (mut energy, mut hypotheses, mut rounds, mut converged) = (0.0, 0, 0, true);
    let mut merge_tests = Vec::new();
    for &(a, b) in windows {
        let tracks: Vec<usize> = (0..n)
            .filter(|&p| {
                let fr = ts.frames_of(p);
                let lo = fr.partition_point(|&x| (x as usize) < a);
                let hi = fr.partition_point(|&x| (x as usize) < b);
                hi - lo >= 3
            })
            .collect();
        let wts = ts.select(a, b, &tracks);
        let seg = match segment_tracks(&wts, cfg, rng, Instant::now(), None) {
            Ok(s) => s,
            Err(Error::TooFew { .. }) | Err(Error::Degenerate(_)) => {
                labels_in.push(Vec::new());
                groups_in.push(Vec::new());
                continue;
            }
            Err(e) => return Err(e),
        };
        energy += seg.energy;
        hypotheses += seg.hypotheses;
        rounds += seg.rounds;
        converged &= seg.converged;
        merge_tests.extend(seg.merge_tests);
        labels_in.push(tracks.iter().copied().zip(seg.labels).collect());
        groups_in.push(
            seg.objects
                .into_iter()
                .map(|o| Piece {
                    tracks: o.tracks.iter().map(|&j| tracks[j]).collect(),
                    model: embed(&o.model, a, nf),
                    pieces: o.pieces,
                })
                .collect(),
        );
    }

    // 3. Links between consecutive windows; `chain[w][g]` = the object of group g of w. A
    //    group of window w that no group of w − 1 continues is linked, the same way, to a
    //    group of w − 2 that no group of w − 1 continued: one window where two bodies
    //    could not be told apart (one group for both) does not cut their chains.
    let mut chain: Vec<Vec<usize>> = Vec::with_capacity(windows.len());
    let mut continued: Vec<Vec<bool>> = Vec::with_capacity(windows.len());
    let mut n_chains = 0;
    for w in 0..windows.len() {
        let mut ids: Vec<Option<usize>> = vec![None; groups_in[w].len()];
        continued.push(vec![false; groups_in[w].len()]);
        if w > 0 {
            for (g, h) in links(
                &labels_in[w - 1],
                &labels_in[w],
                groups_in[w - 1].len(),
                groups_in[w].len(),
                |_| true,
                |_| true,
            ) {
                ids[h] = Some(chain[w - 1][g]);
                continued[w - 1][g] = true;
            }
        }
        if w > 1 {
            let ended = &continued[w - 2];
            let open: Vec<bool> = ids.iter().map(Option::is_none).collect();
            for (g, h) in links(
                &labels_in[w - 2],
                &labels_in[w],
                groups_in[w - 2].len(),
                groups_in[w].len(),
                |g| !ended[g],
                |h| open[h],
            ) {
                ids[h] = Some(chain[w - 2][g]);
            }
        }
        chain.push(
            ids.into_iter()
                .map(|id| {
                    id.unwrap_or_else(|| {
                        n_chains += 1;
                        n_chains - 1
                    })
                })
                .collect(),
        );
    }
    // 4. Each track's majority over its windows (`None` = outlier), ties to the window
    //    nearest its middle frame.
    let mut votes: Vec<Vec<(Option<usize>, usize)>> = vec![Vec::new(); n];
    for (w, labels) in labels_in.iter().enumerate() {
        for &(p, l) in labels {
            match l {
                Label::Object(g) => votes[p].push((Some(chain[w][g]), w)),
                Label::Outlier => votes[p].push((None, w)),
                Label::Unscored => {}
            }
        }
    }
    let centre = |w: usize| (windows[w].0 + windows[w].1) as f64 / 2.0;
    let mut label_of: Vec<Option<Option<usize>>> = vec![None; n];
    for p in 0..n {
        let v = &votes[p];
        if v.is_empty() {
            continue;
        }
        let fr = ts.frames_of(p);
        let mid = (fr[0] + fr[fr.len() - 1]) as f64 / 2.0;
        let best = v
            .iter()
            .map(|&(key, w)| {
                let count = v.iter().filter(|x| x.0 == key).count();
                (key, count, (centre(w) - mid).abs())
            })
            .max_by(|a, b| a.1.cmp(&b.1).then(b.2.total_cmp(&a.2)))
            .map(|x| x.0);
        label_of[p] = best;
    }
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); n_chains];
    for (p, l) in label_of.iter().enumerate() {
        if let Some(Some(c)) = l {
            members[*c].push(p);
        }
    }
    let mut order: Vec<usize> = (0..n_chains)
        .filter(|&c| members[c].len() >= cfg.min_group_tracks)
        .collect();
    order.sort_by(|&a, &b| {
        members[b]
            .len()
            .cmp(&members[a].len())
            .then(members[a][0].cmp(&members[b][0]))
    });

    // 5. Each object's subspace on every frame: its pieces chained, then refitted.
    let mut pieces_of: Vec<Vec<&Piece>> = vec![Vec::new(); n_chains];
    for (w, groups) in groups_in.iter().enumerate() {
        for (g, piece) in groups.iter().enumerate() {
            pieces_of[chain[w][g]].push(piece);
        }
    }
    let mut labels: Vec<Label> = (0..n)
        .map(|p| match label_of[p] {
            None => Label::Unscored,
            Some(_) => Label::Outlier,
        })
        .collect();
    let mut objects = Vec::with_capacity(order.len());
    let mut chis: Vec<Chi> = Vec::with_capacity(order.len());
    for &c in &order {
        let tracks = std::mem::take(&mut members[c]);
        let stitched = stitch(ts, &pieces_of[c]);
        // Refitted to its tracks, unless the refit loses frames the chain defined (a
        // frame where its tracks are too few for the refit's camera).
        let model = match ts.refit_with(&stitched, &tracks, cfg.refit_sweeps) {
            Some(m) if m.n_defined() >= stitched.n_defined() => m,
            _ => stitched,
        };
        chis.push(chi_of(ts, &model));
        objects.push(ObjectGroup {
            rms: 0.0,
            sigma: 0.0,
            model,
            pieces: pieces_of[c].iter().map(|p| p.pieces).max().unwrap_or(1),
            tracks,
        });
    }
    // 6. Objects whose subspaces explain each other's tracks about as well as their own
    //    are one body whose chain broke (a window that split it): merged, the larger
    //    keeping its index, while a pair's separation is below `window_merge_separation`.
    loop {
        let mut worst: Option<(f64, usize, usize)> = None;
        for a in 0..objects.len() {
            for b in a + 1..objects.len() {
                let pair = [&objects[a].tracks, &objects[b].tracks];
                let chi = [&chis[a], &chis[b]];
                if let Some(q) =
                    least_separation(&pair, |i, p| chi[i][p].map_or(f64::INFINITY, |c| c.0))
                    && q < cfg.window_merge_separation
                    && worst.is_none_or(|w| q < w.0)
                {
                    worst = Some((q, a, b));
                }
            }
        }
        let Some((_, a, b)) = worst else {
            break;
        };
        let gone = objects.remove(b);
        chis.remove(b);
        let keep = &mut objects[a];
        keep.tracks.extend(gone.tracks);
        keep.tracks.sort_unstable();
        keep.pieces = keep.pieces.max(gone.pieces);
        if let Some(m) = ts.refit_with(&keep.model, &keep.tracks, cfg.refit_sweeps) {
            keep.model = m;
        }
        chis[a] = chi_of(ts, &keep.model);
    }
    // Largest first.
    let mut paired: Vec<(ObjectGroup, Chi)> = objects.into_iter().zip(chis).collect();
    paired.sort_by(|a, b| {
        let (x, y) = (&a.0.tracks, &b.0.tracks);
        y.len().cmp(&x.len()).then(x[0].cmp(&y[0]))
    });
    let (mut objects, chis): (Vec<ObjectGroup>, Vec<_>) = paired.into_iter().unzip();
    // Labels, RMS and noise under the final subspaces.
    let (mut ss_all, mut dof_all) = (0.0, 0.0);
    for (k, (o, chi)) in objects.iter_mut().zip(&chis).enumerate() {
        let (mut ss, mut dof) = (0.0, 0.0);
        for &p in &o.tracks {
            labels[p] = Label::Object(k);
            if let Some((x, nu)) = chi[p] {
                ss += x;
                dof += nu;
            }
        }
        ss_all += ss;
        dof_all += dof;
        let params = (8.0 * o.model.n_defined() as f64 - 9.0).max(0.0);
        o.rms = (ss / dof.max(1.0)).sqrt();
        o.sigma = (ss / (dof - params).max(1.0)).sqrt();
    }
    let groups: Vec<&Vec<usize>> = objects.iter().map(|o| &o.tracks).collect();
    let separation = least_separation(&groups, |i, p| chis[i][p].map_or(f64::INFINITY, |c| c.0));
    Ok(Segmentation {
        labels,
        objects,
        sigma: (ss_all / dof_all.max(1.0)).sqrt(),
        energy,
        count_rule: CountRule::Windows,
        separation,
        merge_tests,
        label_cost: 0.0,
        hypotheses,
        rounds,
        converged,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Mutual best matches `(g, h)` between the groups of two consecutive windows, by the
/// tracks labelled `g` in the first and `h` in the second (step 3).
fn links(
    first: &[(usize, Label)],
    second: &[(usize, Label)],
    n_first: usize,
    n_second: usize,
    first_ok: impl Fn(usize) -> bool,
    second_ok: impl Fn(usize) -> bool,
) -> Vec<(usize, usize)> {
    let mut count = vec![vec![0usize; n_second]; n_first];
    // Tracks of each group that the other window scored (any label but unscored).
    let (mut both_g, mut both_h) = (vec![0usize; n_first], vec![0usize; n_second]);
    let (mut i, mut j) = (0, 0);
    while i < first.len() && j < second.len() {
        match first[i].0.cmp(&second[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                let (a, b) = (first[i].1, second[j].1);
                let scored = |l: Label| l != Label::Unscored;
                if let Label::Object(g) = a
                    && scored(b)
                {
                    both_g[g] += 1;
                }
                if let Label::Object(h) = b
                    && scored(a)
                {
                    both_h[h] += 1;
                }
                if let (Label::Object(g), Label::Object(h)) = (a, b)
                    && first_ok(g)
                    && second_ok(h)
                {
                    count[g][h] += 1;
                }
                i += 1;
                j += 1;
            }
        }
    }
    let best_h: Vec<Option<usize>> = count
        .iter()
        .map(|row| {
            (0..n_second)
                .filter(|&h| row[h] > 0)
                .max_by_key(|&h| (row[h], usize::MAX - h))
        })
        .collect();
    let best_g: Vec<Option<usize>> = (0..n_second)
        .map(|h| {
            (0..n_first)
                .filter(|&g| count[g][h] > 0)
                .max_by_key(|&g| (count[g][h], usize::MAX - g))
        })
        .collect();
    (0..n_first)
        .filter_map(|g| {
            let h = best_h[g]?;
            let c = count[g][h];
            (best_g[h] == Some(g) && c >= 3 && 4 * c >= both_g[g].min(both_h[h])).then_some((g, h))
        })
        .collect()
}

/// A window's subspace (on the window's frames, from `a`) on the input's `nf` frames,
/// defined on the window's only.
fn embed(m: &AffineSubspace, a: usize, nf: usize) -> AffineSubspace {
    let mut out = AffineSubspace {
        n_frames: nf,
        m: vec![0.0; 6 * nf],
        t: vec![0.0; 2 * nf],
        defined: vec![false; nf],
    };
    for fw in (0..m.n_frames).filter(|&fw| m.defined[fw]) {
        let fg = a + fw;
        out.defined[fg] = true;
        for r in 0..2 {
            let (rw, rg) = (2 * fw + r, 2 * fg + r);
            out.m[3 * rg..3 * rg + 3].copy_from_slice(&m.m[3 * rw..3 * rw + 3]);
            out.t[rg] = m.t[rw];
        }
    }
    out
}

/// One object's pieces (in window order, one per window: links match each group once)
/// chained into the first one's affine frame (step
/// 5): each next piece mapped by the affine map between the coordinates of the tracks it
/// shares with the previous one, its frames not yet defined taken over. The chain stops at
/// a piece that shares fewer than 4 tracks, or an ill-conditioned map, with the previous.
fn stitch(ts: &TrackSubspace, pieces: &[&Piece]) -> AffineSubspace {
    let mut out = pieces[0].model.clone();
    let mut prev = pieces[0].model.clone();
    let mut prev_tracks = &pieces[0].tracks;
    for piece in &pieces[1..] {
        // s_prev ≈ A s + b over the shared tracks: four unknowns per coordinate of s_prev.
        let mut ata = Matrix4::<f64>::zeros();
        let mut atb = [Vector4::<f64>::zeros(); 3];
        let mut shared = 0;
        for &p in &piece.tracks {
            if prev_tracks.binary_search(&p).is_err() {
                continue;
            }
            let (Some(x), Some(y)) = (ts.track_fit(&prev, p), ts.track_fit(&piece.model, p)) else {
                continue;
            };
            let v = Vector4::new(y.s[0], y.s[1], y.s[2], 1.0);
            ata += v * v.transpose();
            for (i, rhs) in atb.iter_mut().enumerate() {
                *rhs += v * x.s[i];
            }
            shared += 1;
        }
        if shared < 4 {
            break;
        }
        let Some(chol) = ata.cholesky() else {
            break;
        };
        let rows: Vec<Vector4<f64>> = atb.iter().map(|r| chol.solve(r)).collect();
        let a = Matrix3::from_fn(|i, j| rows[i][j]);
        let b = [rows[0][3], rows[1][3], rows[2][3]];
        let Some(ainv) = a.try_inverse() else {
            break;
        };
        let svd = a.singular_values();
        if !(svd.min() > 1e-8 * svd.max()) {
            break;
        }
        // The piece in the chain's frame: cameras M A⁻¹, offsets t − M A⁻¹ b.
        let mut mapped = piece.model.clone();
        for f in (0..mapped.n_frames).filter(|&f| mapped.defined[f]) {
            for r in [2 * f, 2 * f + 1] {
                let m = &piece.model.m[3 * r..3 * r + 3];
                let mut row = [0.0; 3];
                for (j, x) in row.iter_mut().enumerate() {
                    *x = (0..3).map(|i| m[i] * ainv[(i, j)]).sum();
                }
                mapped.m[3 * r..3 * r + 3].copy_from_slice(&row);
                mapped.t[r] = piece.model.t[r] - (0..3).map(|j| row[j] * b[j]).sum::<f64>();
                if !out.defined[f] {
                    out.m[3 * r..3 * r + 3].copy_from_slice(&row);
                    out.t[r] = mapped.t[r];
                }
            }
            out.defined[f] = true;
        }
        prev = mapped;
        prev_tracks = &piece.tracks;
    }
    out
}

/// Every track's `(ν_p r²_p, ν_p)` under `model` (its trimmed fit; `None`: not scorable).
fn chi_of(ts: &TrackSubspace, model: &AffineSubspace) -> Chi {
    (0..ts.n_tracks())
        .map(|p| {
            let o = ts.track_fit(model, p)?;
            let nu = super::fit_dof(&o);
            Some((nu * o.rms * o.rms, nu))
        })
        .collect()
}
