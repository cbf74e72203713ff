//! Texture: which view colours each triangle, the atlas of image patches, and per-track
//! colours.
//!
//! **View choice.** A triangle can be textured from a frame that observes its three vertices
//! (the tracker saw them there, so the triangle is not hidden) with the reference view's
//! winding (seen from the front). Its score there is
//! `cos θ · min(1, A / (½·A_max))`: θ the angle between the triangle's normal and the
//! direction to the camera (frontal = 0), `A` its image area and `A_max` the largest over the
//! candidate frames, so the most frontal view wins among those that show it at least half as
//! large as the best (foreshortening and distance both shrink `A`). Views within 5 % of a
//! triangle's best score are "near-best" for it. Few views are then used, so neighbouring
//! triangles share an image patch and seams are fewer: repeatedly, the frame that is
//! near-best for most of the triangles not yet assigned takes them all (greedy set cover);
//! then, in two passes, each triangle takes the near-best view most of its edge neighbours
//! use. Texture is **picked, not blended**: a blend of views ghosts wherever
//! the reconstruction is off by a pixel, a pick keeps each patch sharp.
//!
//! **Atlas.** Edge-connected triangles with the same view form a chart; each chart's image
//! bounding box (padded by `padding_px`) is copied into the atlas, packed in shelves (tallest
//! first) into a width of about `1.15·√(total area)`. When the atlas would exceed
//! `max_atlas_px` on a side, every chart is scaled down by the same factor. Texture
//! coordinates map each triangle corner through its chart's camera (the model's projection of
//! the corner's 3D point, whatever the camera model; the observed position if the model gives
//! none); `(0, 0)` is the atlas's top-left corner (glTF and Rerun; OBJ's `vt` flips `v`).
//!
//! **Colours.** A track's colour is the mean of the frames' bilinear samples at its observed
//! positions.
//!
//! Cost: O(T·c) for the view choice (c frames per triangle), O(atlas pixels + observations)
//! for the frames, which are read once, in order, one at a time.

use std::collections::HashMap;

use image::RgbImage;
use serde::Serialize;

use super::MeshConfig;
use super::scene::Scene;
use super::surface::{Observed, Triangle, common_views, cross2};

/// One chart: triangles textured from the same frame, connected through shared edges.
#[derive(Debug, Clone)]
pub(crate) struct Chart {
    pub(crate) view: u32,
    /// Image box `[x0, y0, x1, y1]` (padding included), pixels of the frame.
    pub(crate) bbox: [f64; 4],
    /// Atlas rectangle `[x, y, w, h]`.
    pub(crate) rect: [u32; 4],
}

/// The texture stage's report.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TextureReport {
    pub charts: usize,
    /// Atlas width and height, pixels.
    pub atlas_px: [u32; 2],
    /// Atlas pixels per image pixel (1 unless the atlas had to shrink).
    pub scale: f64,
    /// Frames that texture at least one triangle.
    pub views_used: usize,
    /// Median over triangles of the angle between the normal and the direction to the chosen
    /// view's camera, degrees.
    pub median_view_angle_deg: f64,
    /// Share of the surface (3D area) textured from a view within 30° of frontal.
    pub share_within_30deg: f64,
    /// Share of the surface (3D area) textured from a view within 5° of its most frontal
    /// candidate view.
    pub share_near_most_frontal: f64,
    /// Median over triangles of the chosen view's angle minus the most frontal candidate's,
    /// degrees.
    pub median_excess_angle_deg: f64,
    /// Frames read, and of those used for the atlas or the colours.
    pub frames_read: usize,
    pub frames_matched: usize,
    /// How input frames were matched to the table's frames: `"id"` or `"position"`.
    pub frames_matched_by: String,
    /// Charts whose frame was not among those read (left black in the atlas).
    pub charts_unfilled: usize,
}

/// A view scoring at least this share of a triangle's best score is "near-best" for it.
const NEAR_BEST: f64 = 0.95;

/// The view of every triangle, the charts and their atlas layout.
pub(crate) struct Plan {
    pub(crate) tri_chart: Vec<u32>,
    pub(crate) charts: Vec<Chart>,
    pub(crate) atlas: [u32; 2],
    pub(crate) scale: f64,
    pub(crate) report: TextureReport,
}

struct Choice {
    /// `(view, score)` within [`NEAR_BEST`] of the best, best first.
    near_best: Vec<(u32, f64)>,
    /// Cosine of the chosen view, and the best cosine among the candidates.
    cos: HashMap<u32, f64>,
    best_cos: f64,
    area: f64,
}

fn observed(tracks: &[Observed], p: u32, f: u32) -> Option<[f64; 2]> {
    let t = &tracks[p as usize];
    t.binary_search_by_key(&f, |o| o.0).ok().map(|i| t[i].1)
}

/// Chooses the views, builds and packs the charts (module documentation).
pub(crate) fn plan(
    scene: &Scene,
    tracks: &[Observed],
    tris: &[Triangle],
    cfg: &MeshConfig,
) -> Plan {
    let pt = |p: u32| scene.points[p as usize].expect("mesh vertices have points");
    let choices: Vec<Choice> = tris
        .iter()
        .map(|t| {
            let x = t.tracks.map(pt);
            let n = (x[1] - x[0]).cross(&(x[2] - x[0]));
            let area = n.norm() / 2.0;
            let n = n.normalize();
            let c = (x[0] + x[1] + x[2]) / 3.0;
            let cands: Vec<(u32, f64, f64)> = common_views(tracks, t.tracks)
                .into_iter()
                .filter_map(|(h, q)| {
                    let a = cross2(q[0], q[1], q[2]) / 2.0;
                    let cos = scene
                        .toward_camera(h as usize, &c)
                        .map_or(1.0, |v| n.dot(&v).abs());
                    (a > 0.0).then_some((h, cos, a))
                })
                .collect();
            let cands = if cands.is_empty() {
                vec![(t.reference, 1.0, 1.0)]
            } else {
                cands
            };
            let a_max = cands.iter().map(|c| c.2).fold(0.0, f64::max);
            let mut scored: Vec<(u32, f64)> = cands
                .iter()
                .map(|&(h, cos, a)| (h, cos * (a / (0.5 * a_max)).min(1.0)))
                .collect();
            scored.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            let best = scored[0].1;
            let near_best = scored
                .into_iter()
                .take_while(|s| s.1 >= NEAR_BEST * best)
                .collect();
            Choice {
                near_best,
                cos: cands.iter().map(|c| (c.0, c.1)).collect(),
                best_cos: cands.iter().map(|c| c.1).fold(0.0, f64::max),
                area,
            }
        })
        .collect();
    // Edge neighbours.
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (i, t) in tris.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (t.tracks[e], t.tracks[(e + 1) % 3]);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push(i as u32);
        }
    }
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); tris.len()];
    for list in edges.values() {
        for &i in list {
            for &j in list {
                if i != j {
                    neighbours[i as usize].push(j);
                }
            }
        }
    }
    // Few views: repeatedly, the frame that is near-best for most unassigned triangles.
    let mut view: Vec<u32> = vec![u32::MAX; tris.len()];
    let mut left = tris.len();
    while left > 0 {
        let mut votes: HashMap<u32, usize> = HashMap::new();
        for (i, c) in choices.iter().enumerate() {
            if view[i] == u32::MAX {
                for &(h, _) in &c.near_best {
                    *votes.entry(h).or_default() += 1;
                }
            }
        }
        let Some((&h, _)) = votes
            .iter()
            .max_by_key(|(h, n)| (**n, std::cmp::Reverse(**h)))
        else {
            break;
        };
        for (i, c) in choices.iter().enumerate() {
            if view[i] == u32::MAX && c.near_best.iter().any(|x| x.0 == h) {
                view[i] = h;
                left -= 1;
            }
        }
    }
    for _ in 0..2 {
        for i in 0..tris.len() {
            let mut best = (0usize, f64::NEG_INFINITY, view[i]);
            for &(h, s) in &choices[i].near_best {
                let votes = neighbours[i]
                    .iter()
                    .filter(|&&j| view[j as usize] == h)
                    .count();
                if (votes, s) > (best.0, best.1) {
                    best = (votes, s, h);
                }
            }
            view[i] = best.2;
        }
    }
    // Charts: union-find over shared edges with the same view.
    let mut parent: Vec<u32> = (0..tris.len() as u32).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for list in edges.values() {
        for w in list.windows(2) {
            if view[w[0] as usize] == view[w[1] as usize] {
                let (a, b) = (root(&mut parent, w[0]), root(&mut parent, w[1]));
                if a != b {
                    parent[a as usize] = b;
                }
            }
        }
    }
    let mut chart_of_root: HashMap<u32, u32> = HashMap::new();
    let mut charts: Vec<Chart> = Vec::new();
    let mut tri_chart = vec![0u32; tris.len()];
    let pad = cfg.padding_px as f64;
    for i in 0..tris.len() {
        let r = root(&mut parent, i as u32);
        let c = *chart_of_root.entry(r).or_insert_with(|| {
            charts.push(Chart {
                view: view[i],
                bbox: [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ],
                rect: [0; 4],
            });
            (charts.len() - 1) as u32
        });
        tri_chart[i] = c;
        let b = &mut charts[c as usize].bbox;
        for p in tris[i].tracks {
            let xy = image_position(scene, tracks, p, view[i]);
            b[0] = b[0].min(xy[0] - pad);
            b[1] = b[1].min(xy[1] - pad);
            b[2] = b[2].max(xy[0] + pad);
            b[3] = b[3].max(xy[1] + pad);
        }
    }
    let (atlas, scale) = pack(&mut charts, cfg.max_atlas_px);
    // Report.
    let total: f64 = choices.iter().map(|c| c.area).sum();
    let mut angles: Vec<f64> = Vec::with_capacity(tris.len());
    let mut excess: Vec<f64> = Vec::with_capacity(tris.len());
    let (mut within30, mut most) = (0.0, 0.0);
    let deg = |cos: f64| cos.clamp(-1.0, 1.0).acos().to_degrees();
    for (i, c) in choices.iter().enumerate() {
        let cos = c.cos.get(&view[i]).copied().unwrap_or(1.0);
        angles.push(deg(cos));
        excess.push(deg(cos) - deg(c.best_cos));
        if deg(cos) <= 30.0 {
            within30 += c.area;
        }
        if deg(cos) <= deg(c.best_cos) + 5.0 {
            most += c.area;
        }
    }
    angles.sort_by(f64::total_cmp);
    excess.sort_by(f64::total_cmp);
    let mut used: Vec<u32> = view.clone();
    used.sort_unstable();
    used.dedup();
    let share = |x: f64| if total > 0.0 { x / total } else { 0.0 };
    Plan {
        tri_chart,
        report: TextureReport {
            charts: charts.len(),
            atlas_px: atlas,
            scale,
            views_used: used.len(),
            median_view_angle_deg: angles.get(angles.len() / 2).copied().unwrap_or(f64::NAN),
            share_within_30deg: share(within30),
            share_near_most_frontal: share(most),
            median_excess_angle_deg: excess.get(excess.len() / 2).copied().unwrap_or(f64::NAN),
            ..Default::default()
        },
        charts,
        atlas,
        scale,
    }
}

/// Shelf packing; returns the atlas size and the scale applied to every chart.
fn pack(charts: &mut [Chart], max_side: u32) -> ([u32; 2], f64) {
    let mut scale = 1.0f64;
    let mut order: Vec<usize> = (0..charts.len()).collect();
    order.sort_by(|&a, &b| {
        let h = |c: &Chart| c.bbox[3] - c.bbox[1];
        h(&charts[b]).total_cmp(&h(&charts[a]))
    });
    loop {
        let size = |c: &Chart| {
            [
                (((c.bbox[2] - c.bbox[0]) * scale).ceil() as u32).max(1) + 1,
                (((c.bbox[3] - c.bbox[1]) * scale).ceil() as u32).max(1) + 1,
            ]
        };
        let area: f64 = charts
            .iter()
            .map(|c| {
                let s = size(c);
                s[0] as f64 * s[1] as f64
            })
            .sum();
        let widest = charts.iter().map(|c| size(c)[0]).max().unwrap_or(1);
        let width = widest.max((1.15 * area.sqrt()).ceil() as u32).max(1);
        let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
        for &i in &order {
            let s = size(&charts[i]);
            if x + s[0] > width {
                x = 0;
                y += shelf;
                shelf = 0;
            }
            charts[i].rect = [x, y, s[0], s[1]];
            x += s[0];
            shelf = shelf.max(s[1]);
        }
        let height = (y + shelf).max(1);
        let side = width.max(height);
        if side <= max_side.max(16) || scale < 1e-3 {
            return ([width, height], scale);
        }
        scale *= 0.95 * max_side as f64 / side as f64;
    }
}

/// Bilinear sample of an RGB image at continuous pixel coordinates (pixel centres at
/// integers), clamped to the image.
pub(crate) fn sample(img: &RgbImage, x: f64, y: f64) -> [f64; 3] {
    let (w, h) = (img.width() as f64, img.height() as f64);
    let x = x.clamp(0.0, w - 1.0);
    let y = y.clamp(0.0, h - 1.0);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as u32, y0 as u32);
    let x1 = (x0 + 1).min(img.width() - 1);
    let y1 = (y0 + 1).min(img.height() - 1);
    let px = |x, y| img.get_pixel(x, y).0.map(f64::from);
    let (a, b, c, d) = (px(x0, y0), px(x1, y0), px(x0, y1), px(x1, y1));
    std::array::from_fn(|k| {
        (a[k] * (1.0 - fx) + b[k] * fx) * (1.0 - fy) + (c[k] * (1.0 - fx) + d[k] * fx) * fy
    })
}

/// Copies chart patches of frame `f` into the atlas.
pub(crate) fn fill_frame(
    plan: &Plan,
    charts_of: &[Vec<u32>],
    f: usize,
    img: &RgbImage,
    atlas: &mut RgbImage,
) {
    let Some(list) = charts_of.get(f) else {
        return;
    };
    for &c in list {
        let ch = &plan.charts[c as usize];
        let [rx, ry, rw, rh] = ch.rect;
        for ay in 0..rh {
            for ax in 0..rw {
                let u = ch.bbox[0] + ax as f64 / plan.scale;
                let v = ch.bbox[1] + ay as f64 / plan.scale;
                let s = sample(img, u, v);
                atlas.put_pixel(
                    rx + ax,
                    ry + ay,
                    image::Rgb(s.map(|c| c.round().clamp(0.0, 255.0) as u8)),
                );
            }
        }
    }
}

/// Texture coordinates (top-left origin, `[0, 1]`) of image position `xy` in chart `c`.
pub(crate) fn uv(plan: &Plan, c: u32, xy: [f64; 2]) -> [f32; 2] {
    let ch = &plan.charts[c as usize];
    let ax = ch.rect[0] as f64 + (xy[0] - ch.bbox[0]) * plan.scale + 0.5;
    let ay = ch.rect[1] as f64 + (xy[1] - ch.bbox[1]) * plan.scale + 0.5;
    [
        (ax / plan.atlas[0] as f64) as f32,
        (ay / plan.atlas[1] as f64) as f32,
    ]
}

/// Where a texture coordinate of track `p` points in frame `f`: the camera model's
/// projection of its point (through the real projection: perspective, projective or affine),
/// or its observed position when the model gives none.
pub(crate) fn image_position(scene: &Scene, tracks: &[Observed], p: u32, f: u32) -> [f64; 2] {
    scene
        .project(f as usize, p as usize)
        .filter(|xy| xy.iter().all(|v| v.is_finite()))
        .or_else(|| observed(tracks, p, f))
        .expect("chosen views observe the vertices")
}
