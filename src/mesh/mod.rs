//! A textured surface from the tracks (the seed's §7.1): "triangulating tracked features
//! (e.g., Delaunay triangulation) and projecting image intensities via texture mapping yields
//! photorealistic 3D models".
//!
//! ```text
//! Reconstruction + track table ─→ Scene (cameras of any model, points, observations)
//!   ─→ surface::triangulate   Delaunay in greedy reference views, triangles the views reject
//!                             dropped (edge-on, long edges, back-facing, free-space, overlap)
//!   ─→ texture::plan          best view per triangle, charts, atlas layout
//!   ─→ frames, read once      atlas patches copied, per-track colours sampled
//!   ─→ Mesh                   positions, texture coordinates, colours, triangles, atlas
//! ```
//!
//! The stages' objectives, rules and costs are documented in [`surface`] and [`texture`];
//! [`export`] writes OBJ + MTL + PNG and binary glTF. Outlier tracks never become vertices
//! (they are coloured, for `points.ply`). Positions are those of the reconstruction's points:
//! the Euclidean (perspective) ones when there is a perspective result, the affine-family
//! ones otherwise; with the projective camera the image positions come from `P_f X_p`.
//!
//! Reference: Tomasi & Kanade 1992 (the textured toy house); the rules that keep a triangle
//! are the standard visibility arguments of image-based modelling (e.g. Morris & Kanade 2000,
//! "Image-consistent surface triangulation"; Labatut et al. 2009 for free-space violations).

pub mod export;
pub mod scene;
pub mod surface;
pub mod texture;

use image::RgbImage;
use serde::Serialize;

pub use scene::{Scene, View};
use surface::Observed;
pub use surface::{SurfaceReport, Triangle};
pub use texture::TextureReport;

use crate::table::Id;
use crate::{Error, Result};

/// Settings of the mesh and texture stages; the defaults are the documented values.
#[derive(Debug, Clone)]
pub struct MeshConfig {
    /// At most this many reference views are triangulated (default 8).
    pub max_reference_views: usize,
    /// A further reference view must observe at least this share of the vertices that no
    /// chosen view observed yet (default 0.05; at least 3 vertices).
    pub min_new_vertices: f64,
    /// Triangles seen more edge-on than this in their reference view are dropped: the
    /// minimum `|cos|` between normal and viewing direction (default 0.2, ≈ 78°).
    pub min_view_cos: f64,
    /// A triangle with a 3D edge longer than this many times its endpoints' local spacing is
    /// dropped (default 3).
    pub max_edge_ratio: f64,
    /// Views per triangle checked for back-facing and free-space violations (default 6).
    pub check_views: usize,
    /// Largest atlas side, pixels; charts shrink to fit (default 8192).
    pub max_atlas_px: u32,
    /// Pixels of image around each chart, for filtering at the seams (default 2).
    pub padding_px: u32,
}

impl Default for MeshConfig {
    fn default() -> Self {
        MeshConfig {
            max_reference_views: 8,
            min_new_vertices: 0.05,
            min_view_cos: 0.2,
            max_edge_ratio: 3.0,
            check_views: 6,
            max_atlas_px: 8192,
            padding_px: 2,
        }
    }
}

impl MeshConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        let bad = |field: &'static str, message: &str| {
            Err(Error::InvalidConfig {
                field,
                message: message.to_string(),
            })
        };
        if self.max_reference_views == 0 {
            return bad("max_reference_views", "must be at least 1");
        }
        if !(0.0..=1.0).contains(&self.min_new_vertices) {
            return bad("min_new_vertices", "must be in [0, 1]");
        }
        if !(0.0..1.0).contains(&self.min_view_cos) {
            return bad("min_view_cos", "must be in [0, 1)");
        }
        if !(self.max_edge_ratio.is_finite() && self.max_edge_ratio > 1.0) {
            return bad("max_edge_ratio", "must be a finite number above 1");
        }
        if !(16..=32768).contains(&self.max_atlas_px) {
            return bad("max_atlas_px", "must be in [16, 32768]");
        }
        if self.padding_px > 64 {
            return bad("padding_px", "must be at most 64");
        }
        Ok(())
    }
}

/// What the mesh stages did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MeshReport {
    pub surface: SurfaceReport,
    /// Present when frames were given.
    pub texture: Option<TextureReport>,
    pub seconds_surface: f64,
    pub seconds_texture: f64,
}

/// A triangle mesh with texture coordinates into one atlas image.
///
/// Vertices are (track, chart) pairs: a track on the border of two charts appears once per
/// chart, with the same position and different texture coordinates.
#[derive(Debug, Clone, Default)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    /// Top-left origin, `[0, 1]²` (empty without frames).
    pub texcoords: Vec<[f32; 2]>,
    /// Per-vertex colour (grey without frames).
    pub colors: Vec<[u8; 3]>,
    /// Unit per-vertex normals (area-weighted mean of the adjacent triangles' normals, each
    /// turned towards its reference view's camera).
    pub normals: Vec<[f32; 3]>,
    /// Counter-clockwise seen from the side the normals point to.
    pub triangles: Vec<[u32; 3]>,
    /// Input track index of every vertex.
    pub vertex_tracks: Vec<u32>,
    /// The texture atlas (`None` without frames).
    pub texture: Option<RgbImage>,
    /// Colour of every input track observed in a frame read (outliers too), for `points.ply`.
    pub track_colors: Vec<Option<[u8; 3]>>,
    pub report: MeshReport,
}

/// A source of frames: the next frame and its id, `None` at the end.
pub type FrameFeed<'a> = &'a mut dyn FnMut() -> Result<Option<(Id, RgbImage)>>;

/// Builds the mesh of `scene`; with `frames`, its texture and the tracks' colours (module
/// documentation). Frames are matched to the scene's by id, or by position when the first
/// frame's id is not one of the scene's.
pub fn build(scene: &Scene, cfg: &MeshConfig, frames: Option<FrameFeed<'_>>) -> Result<Mesh> {
    cfg.validate()?;
    let t0 = std::time::Instant::now();
    let tracks = surface::by_track(scene);
    let (tris, surface) = surface::triangulate(scene, &tracks, cfg);
    let seconds_surface = t0.elapsed().as_secs_f64();
    let Some(frames) = frames else {
        let mut mesh = assemble(scene, &tris, vec![None; scene.n_tracks()], None);
        mesh.report = MeshReport {
            surface,
            texture: None,
            seconds_surface,
            seconds_texture: 0.0,
        };
        return Ok(mesh);
    };
    let t1 = std::time::Instant::now();
    let mut plan = texture::plan(scene, &tracks, &tris, cfg);
    let mut charts_of: Vec<Vec<u32>> = vec![Vec::new(); scene.n_frames()];
    for (c, ch) in plan.charts.iter().enumerate() {
        charts_of[ch.view as usize].push(c as u32);
    }
    let mut atlas = RgbImage::new(plan.atlas[0], plan.atlas[1]);
    let mut sums = vec![[0.0f64; 4]; scene.n_tracks()];
    let index: std::collections::HashMap<&Id, usize> = scene
        .frame_ids
        .iter()
        .enumerate()
        .map(|(i, id)| (id, i))
        .collect();
    let mut by_id = None;
    let (mut read, mut matched) = (0usize, 0usize);
    let mut filled = vec![false; scene.n_frames()];
    while let Some((id, img)) = frames()? {
        let by_id = *by_id.get_or_insert(index.contains_key(&id));
        let f = if by_id {
            index.get(&id).copied()
        } else {
            Some(read).filter(|&i| i < scene.n_frames())
        };
        read += 1;
        let Some(f) = f else { continue };
        matched += 1;
        filled[f] = true;
        texture::fill_frame(&plan, &charts_of, f, &img, &mut atlas);
        for &(p, xy) in &scene.observations[f] {
            let s = texture::sample(&img, xy[0], xy[1]);
            let acc = &mut sums[p as usize];
            for k in 0..3 {
                acc[k] += s[k];
            }
            acc[3] += 1.0;
        }
    }
    if matched == 0 {
        return Err(Error::InvalidConfig {
            field: "frames",
            message: format!(
                "none of the {read} frames given matches a frame of the track table ({} frames)",
                scene.n_frames()
            ),
        });
    }
    plan.report.frames_read = read;
    plan.report.frames_matched = matched;
    plan.report.frames_matched_by = if by_id == Some(true) {
        "id"
    } else {
        "position"
    }
    .into();
    let track_colors: Vec<Option<[u8; 3]>> = sums
        .iter()
        .map(|s| (s[3] > 0.0).then(|| std::array::from_fn(|k| (s[k] / s[3]).round() as u8)))
        .collect();
    let mut mesh = assemble(scene, &tris, track_colors, Some((&plan, &tracks)));
    mesh.texture = Some(atlas);
    mesh.report = MeshReport {
        surface,
        texture: Some(plan.report),
        seconds_surface,
        seconds_texture: t1.elapsed().as_secs_f64(),
    };
    Ok(mesh)
}

/// The mesh's vertices and triangles: one vertex per track, or per (track, chart) with a
/// texture (the chart's camera maps it into the atlas); colours from `track_colors` (grey
/// where a track has none); then [`orient`].
fn assemble(
    scene: &Scene,
    tris: &[Triangle],
    track_colors: Vec<Option<[u8; 3]>>,
    textured: Option<(&texture::Plan, &[Observed])>,
) -> Mesh {
    let mut mesh = Mesh::default();
    let mut index = std::collections::HashMap::new();
    for (i, t) in tris.iter().enumerate() {
        let chart = textured.map(|(plan, _)| plan.tri_chart[i]);
        let tri = t.tracks.map(|p| {
            *index.entry((p, chart)).or_insert_with(|| {
                let x = scene.points[p as usize].expect("vertices have points");
                mesh.positions.push([x[0] as f32, x[1] as f32, x[2] as f32]);
                if let (Some(c), Some((plan, tracks))) = (chart, textured) {
                    let view = plan.charts[c as usize].view;
                    let xy = texture::image_position(scene, tracks, p, view);
                    mesh.texcoords.push(texture::uv(plan, c, xy));
                }
                mesh.colors
                    .push(track_colors[p as usize].unwrap_or([180, 180, 180]));
                mesh.vertex_tracks.push(p);
                (mesh.positions.len() - 1) as u32
            })
        });
        mesh.triangles.push(tri);
    }
    mesh.track_colors = track_colors;
    orient(&mut mesh, scene, tris);
    mesh
}

/// Turns every triangle towards its reference view's camera (counter-clockwise seen from
/// there) and sets the vertex normals.
fn orient(mesh: &mut Mesh, scene: &Scene, tris: &[Triangle]) {
    let mut acc = vec![nalgebra::Vector3::<f64>::zeros(); mesh.positions.len()];
    for (t, src) in mesh.triangles.iter_mut().zip(tris) {
        let x = t.map(|i| {
            let p = mesh.positions[i as usize];
            nalgebra::Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        });
        let mut n = (x[1] - x[0]).cross(&(x[2] - x[0]));
        let c = (x[0] + x[1] + x[2]) / 3.0;
        if let Some(v) = scene.toward_camera(src.reference as usize, &c)
            && n.dot(&v) < 0.0
        {
            t.swap(1, 2);
            n = -n;
        }
        for &i in t.iter() {
            acc[i as usize] += n;
        }
    }
    mesh.normals = acc
        .iter()
        .map(|n| {
            let n = n.try_normalize(1e-300).unwrap_or(nalgebra::Vector3::z());
            [n[0] as f32, n[1] as f32, n[2] as f32]
        })
        .collect();
}

/// [`build`] on a reconstruction of `table`, textured from the frames at `frames` (a folder
/// of images or a video, as the tracker reads them).
pub fn from_frames(
    rec: &crate::Reconstruction,
    table: &crate::TrackTable,
    frames: &std::path::Path,
    image_size: Option<[u32; 2]>,
    cfg: &MeshConfig,
) -> Result<Mesh> {
    let scene = Scene::from_reconstruction(rec, table, image_size)?;
    let mut source = crate::tracking::FrameSource::open_color(frames)?;
    let mut feed = || source.next_color_frame();
    build(&scene, cfg, Some(&mut feed))
}

#[cfg(test)]
mod tests;
