//! The triangulated surface: Delaunay triangulations in chosen reference views, kept only
//! where the views agree that the triangle is a piece of surface.
//!
//! Reference views are chosen greedily (maximum coverage): the frame that observes the most
//! vertices not yet considered, until a frame would bring fewer than
//! `max(3, min_new_vertices · n)` new ones or `max_reference_views` are chosen. In each, the
//! observed positions of its vertices are Delaunay-triangulated (spade's bulk loader,
//! O(m log m) for m points) and each triangle `(a, b, c)` is kept unless
//!
//! * **degenerate**: zero area in the image or in 3D;
//! * **edge-on** in its reference view: `|n̂·v̂| < min_view_cos` (n̂ the triangle's normal, v̂
//!   the direction to the camera);
//! * **long edge**: a 3D edge `|X_a − X_b| > max_edge_ratio · max(s_a, s_b)`, `s_v` the median
//!   3D length of `v`'s Delaunay edges in that view. This removes triangles that bridge a depth
//!   discontinuity (short in the image, long in 3D), the slivers along the convex hull and
//!   triangles over textureless gaps, whose edges are much longer than their neighbours';
//! * **back-facing**: in the views that observe all three vertices (up to `check_views` of
//!   them, spread over the sequence), its image winding differs from the reference view's in
//!   more than a quarter: a surface seen from the front everywhere it is seen keeps its
//!   orientation, a triangle folded over an occluding edge does not;
//! * **occluding** (perspective only, where depth order is known): in one of those views an
//!   observed track falls inside the triangle's image and lies behind the triangle's plane
//!   (perspective-correct depth, `1/z` interpolated) by more than twice the triangle's mean
//!   edge: a real surface would hide it (free-space violation);
//! * **overlap**: its image interior intersects a triangle already kept from an earlier
//!   reference view whose three vertices are also observed here (the surfaces of two reference
//!   views meet along a seam instead of overlapping; triangles with the same three vertices
//!   count once).
//!
//! Cost: O(m log m) per reference view for the triangulation, O(T·check_views·k) for the view
//! checks (k tracks per triangle footprint, found through a uniform grid), memory linear in
//! the observations.

use std::collections::HashSet;

use nalgebra::Vector3;
use serde::Serialize;
use spade::{DelaunayTriangulation, HasPosition, Point2, Triangulation};

use super::MeshConfig;
use super::scene::Scene;
use crate::table::Id;

/// One kept triangle: input track indices, counter-clockwise in its reference view's image
/// (x right, y down: the signed area `(b−a)×(c−a)` is positive).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Triangle {
    pub tracks: [u32; 3],
    /// Input frame index of the reference view it came from.
    pub reference: u32,
}

/// A reference view and what it contributed.
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceView {
    pub frame: Id,
    /// Vertices observed in this frame.
    pub observed: usize,
    /// Of those, vertices no earlier reference view observed (why it was chosen).
    pub new_vertices: usize,
    /// Triangles of its Delaunay triangulation, and those kept.
    pub candidates: usize,
    pub kept: usize,
}

/// Triangles dropped, per reason (the module documentation defines each).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Dropped {
    pub degenerate: usize,
    pub edge_on: usize,
    pub long_edge: usize,
    pub back_facing: usize,
    pub occluding: usize,
    pub overlap: usize,
    pub duplicate: usize,
}

/// The triangulation stage's report.
#[derive(Debug, Clone, Default, Serialize)]
pub struct SurfaceReport {
    /// Tracks eligible as vertices (inliers with a 3D point).
    pub eligible_tracks: usize,
    /// Tracks used by at least one kept triangle.
    pub vertices: usize,
    pub triangles: usize,
    pub reference_views: Vec<ReferenceView>,
    pub dropped: Dropped,
}

struct Vertex {
    pos: Point2<f64>,
    track: u32,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.pos
    }
}

/// Twice the signed area of the image triangle.
pub(crate) fn cross2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// A uniform grid over image boxes, for "what is near this box" queries.
pub(crate) struct Grid {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    cells: Vec<Vec<u32>>,
}

impl Grid {
    /// A grid over `[x0, x1] × [y0, y1]` with about `target` cells.
    pub(crate) fn new(bbox: [f64; 4], target: usize) -> Grid {
        let (w, h) = ((bbox[2] - bbox[0]).max(1e-9), (bbox[3] - bbox[1]).max(1e-9));
        let cell = ((w * h) / target.max(1) as f64).sqrt().max(1e-9);
        let nx = ((w / cell).ceil() as usize).clamp(1, 4096);
        let ny = ((h / cell).ceil() as usize).clamp(1, 4096);
        Grid {
            x0: bbox[0],
            y0: bbox[1],
            cell,
            nx,
            ny,
            cells: vec![Vec::new(); nx * ny],
        }
    }

    fn range(&self, b: [f64; 4]) -> (usize, usize, usize, usize) {
        let ix = |x: f64| (((x - self.x0) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let iy = |y: f64| (((y - self.y0) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        (ix(b[0]), ix(b[2]), iy(b[1]), iy(b[3]))
    }

    pub(crate) fn insert(&mut self, item: u32, b: [f64; 4]) {
        let (x0, x1, y0, y1) = self.range(b);
        for y in y0..=y1 {
            for x in x0..=x1 {
                self.cells[y * self.nx + x].push(item);
            }
        }
    }

    /// Items whose boxes may meet `b` (each once: `seen` is a stamp buffer).
    pub(crate) fn query(&self, b: [f64; 4], seen: &mut Stamp, out: &mut Vec<u32>) {
        out.clear();
        seen.next();
        let (x0, x1, y0, y1) = self.range(b);
        for y in y0..=y1 {
            for x in x0..=x1 {
                for &i in &self.cells[y * self.nx + x] {
                    if seen.mark(i as usize) {
                        out.push(i);
                    }
                }
            }
        }
    }
}

/// A "seen in this round" set without clearing.
pub(crate) struct Stamp {
    marks: Vec<u32>,
    round: u32,
}

impl Stamp {
    pub(crate) fn new() -> Stamp {
        Stamp {
            marks: Vec::new(),
            round: 0,
        }
    }
    fn next(&mut self) {
        self.round += 1;
    }
    /// True the first time `i` is marked this round.
    fn mark(&mut self, i: usize) -> bool {
        if i >= self.marks.len() {
            self.marks.resize(i + 1, 0);
        }
        let fresh = self.marks[i] != self.round;
        self.marks[i] = self.round;
        fresh
    }
}

fn bbox(pts: &[[f64; 2]]) -> [f64; 4] {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in pts {
        b[0] = b[0].min(p[0]);
        b[1] = b[1].min(p[1]);
        b[2] = b[2].max(p[0]);
        b[3] = b[3].max(p[1]);
    }
    b
}

/// True when the interiors of two counter-clockwise image triangles intersect (separating
/// axis test on their six edges, with a tolerance `eps` in pixels).
pub(crate) fn interiors_meet(t: &[[f64; 2]; 3], u: &[[f64; 2]; 3], eps: f64) -> bool {
    let separated = |a: &[[f64; 2]; 3], b: &[[f64; 2]; 3]| {
        (0..3).any(|e| {
            let (p, q) = (a[e], a[(e + 1) % 3]);
            let len = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
            b.iter().all(|&r| cross2(p, q, r) <= eps * len)
        })
    };
    !(separated(t, u) || separated(u, t))
}

/// Barycentric coordinates of `x` in the image triangle (None when degenerate).
pub(crate) fn barycentric(t: &[[f64; 2]; 3], x: [f64; 2]) -> Option<[f64; 3]> {
    let d = cross2(t[0], t[1], t[2]);
    if d.abs() < 1e-300 {
        return None;
    }
    let b1 = cross2(t[0], x, t[2]) / d;
    let b2 = cross2(t[0], t[1], x) / d;
    Some([1.0 - b1 - b2, b1, b2])
}

/// One track's observations: `(frame, [x, y])`, frame ascending.
pub(crate) type Observed = Vec<(u32, [f64; 2])>;

/// The observations of every track in the frames that have a camera. Built once per mesh and
/// shared by the stages.
pub(crate) fn by_track(scene: &Scene) -> Vec<Observed> {
    let mut out = vec![Vec::new(); scene.n_tracks()];
    for (f, obs) in scene.observations.iter().enumerate() {
        if scene.views[f].is_none() {
            continue;
        }
        for &(p, xy) in obs {
            out[p as usize].push((f as u32, xy));
        }
    }
    out
}

/// Frames observing all three tracks, with their observed positions.
pub(crate) fn common_views(tracks: &[Observed], tri: [u32; 3]) -> Vec<(u32, [[f64; 2]; 3])> {
    let [a, b, c] = tri.map(|p| &tracks[p as usize]);
    let (mut i, mut j, mut k) = (0, 0, 0);
    let mut out = Vec::new();
    while i < a.len() && j < b.len() && k < c.len() {
        let m = a[i].0.max(b[j].0).max(c[k].0);
        if a[i].0 == m && b[j].0 == m && c[k].0 == m {
            out.push((m, [a[i].1, b[j].1, c[k].1]));
            i += 1;
            j += 1;
            k += 1;
        } else {
            if a[i].0 < m {
                i += 1;
            }
            if j < b.len() && b[j].0 < m {
                j += 1;
            }
            if k < c.len() && c[k].0 < m {
                k += 1;
            }
        }
    }
    out
}

/// Triangulates the scene's inlier points (module documentation); `tracks` is
/// [`by_track`] of the scene.
pub(crate) fn triangulate(
    scene: &Scene,
    tracks: &[Observed],
    cfg: &MeshConfig,
) -> (Vec<Triangle>, SurfaceReport) {
    let nt = scene.n_tracks();
    let eligible: Vec<bool> = (0..nt)
        .map(|p| scene.inlier[p] && scene.points[p].is_some())
        .collect();
    let n_eligible = eligible.iter().filter(|&&e| e).count();
    let mut report = SurfaceReport {
        eligible_tracks: n_eligible,
        ..Default::default()
    };
    let pt = |p: u32| scene.points[p as usize].expect("eligible tracks have points");
    let observed_eligible = |f: usize| -> Vec<(u32, [f64; 2])> {
        scene.observations[f]
            .iter()
            .filter(|(p, _)| eligible[*p as usize])
            .copied()
            .collect()
    };
    let mut considered = vec![false; nt];
    let mut chosen = vec![false; scene.n_frames()];
    let mut kept: Vec<Triangle> = Vec::new();
    let mut keys: HashSet<[u32; 3]> = HashSet::new();
    let min_new = 3usize.max((cfg.min_new_vertices * n_eligible as f64).ceil() as usize);
    let has_depth = scene.has_depth();
    let mut stamp = Stamp::new();
    let mut near = Vec::new();
    let mut view_grids: Vec<Option<ViewGrid>> = (0..scene.n_frames()).map(|_| None).collect();
    for _ in 0..cfg.max_reference_views {
        let best = (0..scene.n_frames())
            .filter(|&f| !chosen[f] && scene.views[f].is_some())
            .map(|f| {
                let new = scene.observations[f]
                    .iter()
                    .filter(|(p, _)| eligible[*p as usize] && !considered[*p as usize])
                    .count();
                (new, std::cmp::Reverse(f), f)
            })
            .max();
        let Some((new, _, g)) = best else { break };
        if new < min_new {
            break;
        }
        chosen[g] = true;
        let obs = observed_eligible(g);
        for (p, _) in &obs {
            considered[*p as usize] = true;
        }
        let mut rv = ReferenceView {
            frame: scene.frame_ids[g].clone(),
            observed: obs.len(),
            new_vertices: new,
            candidates: 0,
            kept: 0,
        };
        let verts: Vec<Vertex> = obs
            .iter()
            .filter(|(_, xy)| xy[0].is_finite() && xy[1].is_finite())
            .map(|&(p, xy)| Vertex {
                pos: Point2::new(xy[0], xy[1]),
                track: p,
            })
            .collect();
        let Ok(dt) = DelaunayTriangulation::<Vertex>::bulk_load(verts) else {
            report.reference_views.push(rv);
            continue;
        };
        // Local spacing: median 3D length of each vertex's Delaunay edges.
        let mut spacing = std::collections::HashMap::new();
        for v in dt.vertices() {
            let x = pt(v.data().track);
            let mut lens: Vec<f64> = v
                .out_edges()
                .map(|e| (pt(e.to().data().track) - x).norm())
                .collect();
            lens.sort_by(f64::total_cmp);
            spacing.insert(
                v.data().track,
                lens.get(lens.len() / 2).copied().unwrap_or(0.0),
            );
        }
        let xy_in_g: std::collections::HashMap<u32, [f64; 2]> = obs.iter().copied().collect();
        // Triangles kept from earlier views whose vertices are all observed here.
        let earlier: Vec<[[f64; 2]; 3]> = kept
            .iter()
            .filter_map(|t| {
                let q = t.tracks.map(|p| xy_in_g.get(&p).copied());
                Some([q[0]?, q[1]?, q[2]?])
            })
            .map(|mut q| {
                if cross2(q[0], q[1], q[2]) < 0.0 {
                    q.swap(1, 2);
                }
                q
            })
            .collect();
        let all: Vec<[f64; 2]> = obs.iter().map(|o| o.1).collect();
        let extent = bbox(&all);
        let diag = ((extent[2] - extent[0]).powi(2) + (extent[3] - extent[1]).powi(2)).sqrt();
        let mut grid = Grid::new(extent, earlier.len().max(16));
        for (i, q) in earlier.iter().enumerate() {
            grid.insert(i as u32, bbox(q));
        }
        for face in dt.inner_faces() {
            rv.candidates += 1;
            let mut tri = face.vertices().map(|v| v.data().track);
            let mut q = tri.map(|p| xy_in_g[&p]);
            let a2 = cross2(q[0], q[1], q[2]);
            if a2 < 0.0 {
                tri.swap(1, 2);
                q.swap(1, 2);
            }
            let mut key = tri;
            key.sort_unstable();
            if keys.contains(&key) {
                report.dropped.duplicate += 1;
                continue;
            }
            let x = tri.map(pt);
            let n = (x[1] - x[0]).cross(&(x[2] - x[0]));
            if a2.abs() <= 1e-12 * diag * diag || n.norm() <= 0.0 || !n.norm().is_finite() {
                report.dropped.degenerate += 1;
                continue;
            }
            let centroid = (x[0] + x[1] + x[2]) / 3.0;
            let n = n.normalize();
            let cos = scene
                .toward_camera(g, &centroid)
                .map_or(1.0, |v| n.dot(&v).abs());
            if cos < cfg.min_view_cos {
                report.dropped.edge_on += 1;
                continue;
            }
            let long = (0..3).any(|e| {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                let len = (pt(a) - pt(b)).norm();
                len > cfg.max_edge_ratio * spacing[&a].max(spacing[&b])
            });
            if long {
                report.dropped.long_edge += 1;
                continue;
            }
            grid.query(bbox(&q), &mut stamp, &mut near);
            if near
                .iter()
                .any(|&i| interiors_meet(&q, &earlier[i as usize], 1e-6 * diag))
            {
                report.dropped.overlap += 1;
                continue;
            }
            match check_views(
                scene,
                tracks,
                tri,
                g,
                &x,
                cfg.check_views,
                has_depth,
                &mut view_grids,
                (&mut stamp, &mut near),
            ) {
                Verdict::Keep => {}
                Verdict::BackFacing => {
                    report.dropped.back_facing += 1;
                    continue;
                }
                Verdict::Occluding => {
                    report.dropped.occluding += 1;
                    continue;
                }
            }
            keys.insert(key);
            kept.push(Triangle {
                tracks: tri,
                reference: g as u32,
            });
            rv.kept += 1;
        }
        report.reference_views.push(rv);
    }
    let mut used = vec![false; nt];
    for t in &kept {
        for p in t.tracks {
            used[p as usize] = true;
        }
    }
    report.vertices = used.iter().filter(|&&u| u).count();
    report.triangles = kept.len();
    (kept, report)
}

/// A frame's observations and a grid over their positions (built when first needed).
type ViewGrid = (Grid, Vec<(u32, [f64; 2])>);

enum Verdict {
    Keep,
    BackFacing,
    Occluding,
}

/// The back-facing and free-space checks of one triangle in up to `max_views` other views
/// that observe its three vertices.
#[allow(clippy::too_many_arguments)]
fn check_views(
    scene: &Scene,
    tracks: &[Observed],
    tri: [u32; 3],
    g: usize,
    x: &[Vector3<f64>; 3],
    max_views: usize,
    has_depth: bool,
    view_grids: &mut [Option<ViewGrid>],
    (stamp, near): (&mut Stamp, &mut Vec<u32>),
) -> Verdict {
    let common: Vec<_> = common_views(tracks, tri)
        .into_iter()
        .filter(|(h, _)| *h as usize != g)
        .collect();
    if common.is_empty() || max_views == 0 {
        return Verdict::Keep;
    }
    let step = common.len().div_ceil(max_views).max(1);
    let mut checked = 0usize;
    let mut flipped = 0usize;
    let mean_edge = ((x[1] - x[0]).norm() + (x[2] - x[1]).norm() + (x[0] - x[2]).norm()) / 3.0;
    for (h, q) in common.iter().step_by(step) {
        let h = *h as usize;
        checked += 1;
        if cross2(q[0], q[1], q[2]) <= 0.0 {
            flipped += 1;
            continue;
        }
        if !has_depth {
            continue;
        }
        let Some(z) = x
            .iter()
            .map(|xi| scene.depth(h, xi).filter(|z| *z > 0.0))
            .collect::<Option<Vec<f64>>>()
        else {
            continue;
        };
        let (grid, pts) = view_grids[h].get_or_insert_with(|| {
            let pts = scene.observations[h].clone();
            let all: Vec<[f64; 2]> = pts.iter().map(|o| o.1).collect();
            let mut grid = Grid::new(bbox(&all), pts.len().max(16));
            for (i, o) in pts.iter().enumerate() {
                grid.insert(i as u32, [o.1[0], o.1[1], o.1[0], o.1[1]]);
            }
            (grid, pts)
        });
        grid.query(bbox(q), stamp, near);
        for &i in near.iter() {
            let (p, xy) = pts[i as usize];
            if tri.contains(&p) || !scene.inlier[p as usize] {
                continue;
            }
            let Some(b) = barycentric(q, xy) else {
                continue;
            };
            if b.iter().any(|&v| v <= 0.02) {
                continue;
            }
            let Some(xp) = scene.points[p as usize] else {
                continue;
            };
            let Some(zp) = scene.depth(h, &xp) else {
                continue;
            };
            let z_plane = 1.0 / (b[0] / z[0] + b[1] / z[1] + b[2] / z[2]);
            if zp - z_plane > 2.0 * mean_edge {
                return Verdict::Occluding;
            }
        }
    }
    if 4 * flipped > checked {
        Verdict::BackFacing
    } else {
        Verdict::Keep
    }
}
