use rerun::{Image, RecordingStream, TextDocument};

use crate::Reconstruction;

use super::{RecordingResult, at_stage, paths};

/// Logs the textured surface at the `mesh` stage: [`paths::PERSPECTIVE_MESH`] beside the
/// Euclidean points when `r` has a perspective result, else [`paths::MESH`] beside the
/// affine-family ones (the positions the mesh was built on); the atlas is the albedo texture
/// (the per-vertex colours are used only without one: the viewer multiplies the two);
/// [`paths::MESH_REPORT`] holds its report.
pub fn log_mesh(
    rec: &RecordingStream,
    r: &Reconstruction,
    mesh: &crate::mesh::Mesh,
) -> RecordingResult {
    at_stage(rec, "mesh");
    let path = if r.perspective.is_some() {
        paths::PERSPECTIVE_MESH
    } else {
        paths::MESH
    };
    let mut m = rerun::Mesh3D::new(mesh.positions.iter().copied())
        .with_triangle_indices(
            mesh.triangles
                .iter()
                .map(|t| rerun::TriangleIndices::from(*t)),
        )
        .with_vertex_normals(mesh.normals.iter().copied());
    if mesh.texture.is_none() {
        m = m.with_vertex_colors(
            mesh.colors
                .iter()
                .map(|c| rerun::Color::from_rgb(c[0], c[1], c[2])),
        );
    }
    if let Some(tex) = &mesh.texture {
        m = m
            .with_vertex_texcoords(mesh.texcoords.iter().copied())
            .with_albedo_texture_image(Image::from_rgb24(
                tex.as_raw().clone(),
                [tex.width(), tex.height()],
            ));
    }
    rec.log_static(path, &m)?;
    let rep = &mesh.report;
    let s = &rep.surface;
    let mut md = format!(
        "# Mesh\n\n{} triangles over {} of {} eligible tracks; {:.3} s triangulating, {:.3} s \
         texturing.\n\n| reference view | observed | new | candidates | kept |\n|---|---|---|---|---|\n",
        s.triangles, s.vertices, s.eligible_tracks, rep.seconds_surface, rep.seconds_texture
    );
    for v in &s.reference_views {
        md += &format!(
            "| {} | {} | {} | {} | {} |\n",
            v.frame, v.observed, v.new_vertices, v.candidates, v.kept
        );
    }
    let d = &s.dropped;
    md += &format!(
        "\nDropped: {} degenerate, {} edge-on, {} long edge, {} back-facing, {} occluding, {} \
         overlapping, {} duplicates.\n",
        d.degenerate, d.edge_on, d.long_edge, d.back_facing, d.occluding, d.overlap, d.duplicate
    );
    if let Some(t) = &rep.texture {
        md += &format!(
            "\nTexture: {} charts from {} frames, atlas {}×{} px (scale {:.3}); median view angle \
             {:.1}°, {:.1} % of the area within 30° of frontal, {:.1} % within 5° of its most frontal view.\n",
            t.charts,
            t.views_used,
            t.atlas_px[0],
            t.atlas_px[1],
            t.scale,
            t.median_view_angle_deg,
            100.0 * t.share_within_30deg,
            100.0 * t.share_near_most_frontal
        );
    }
    rec.log_static(paths::MESH_REPORT, &TextDocument::from_markdown(md))?;
    Ok(())
}
