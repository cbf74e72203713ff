//! Mesh files: Wavefront OBJ + MTL + PNG atlas, and binary glTF 2.0 (one `.glb` with the
//! texture embedded). Every file is written whole ([`crate::atomic`]).
//!
//! * `mesh.obj`: `v x y z r g b` (positions with per-vertex colour in `[0, 1]`, the extension
//!   MeshLab, Open3D and trimesh read), `vn` normals, `vt u v` (OBJ's `v` points up: `1 − v`
//!   of the atlas), `f a/a/a b/b/b c/c/c` (1-based), material `rank3_texture` from
//!   `mesh.mtl`.
//! * `mesh.mtl`: `map_Kd mesh_texture.png`.
//! * `mesh.glb`: one mesh, one primitive: `POSITION` (float3, with the bounds glTF requires),
//!   `NORMAL`, `TEXCOORD_0` (float2, top-left origin as glTF defines it) with a texture,
//!   else `COLOR_0` (normalised ubyte4; glTF would multiply the texture by it),
//!   `u32` indices; the PNG in a buffer view; an unlit (`KHR_materials_unlit`), double-sided
//!   material, since the colours are already the images'. rank3's world has the first
//!   camera's axes (x right, y down, z forward, as in the images) and glTF's is y-up: the node
//!   turns the mesh by 180° about x, so viewers show it upright (the data are not changed).

use std::fmt::Write as _;
use std::path::Path;

use serde_json::json;

use super::Mesh;
use crate::{Error, Result};

/// File names written by [`write_all`].
pub const MESH_FILES: [&str; 4] = ["mesh.obj", "mesh.mtl", "mesh_texture.png", "mesh.glb"];

/// PNG bytes of the atlas.
pub fn texture_png(mesh: &Mesh) -> Result<Option<Vec<u8>>> {
    let Some(img) = &mesh.texture else {
        return Ok(None);
    };
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| Error::Image {
            path: "mesh_texture.png".into(),
            message: format!("cannot encode the texture: {e}"),
        })?;
    Ok(Some(out.into_inner()))
}

/// The OBJ text (`mtllib` named `mtl_name` when there is a texture).
pub fn obj_text(mesh: &Mesh, mtl_name: &str) -> String {
    let mut s = String::with_capacity(64 * mesh.positions.len() + 32 * mesh.triangles.len());
    let _ = writeln!(
        s,
        "# rank3 textured mesh: {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    let textured = mesh.texture.is_some();
    if textured {
        let _ = writeln!(s, "mtllib {mtl_name}");
    }
    for (x, c) in mesh.positions.iter().zip(&mesh.colors) {
        let _ = writeln!(
            s,
            "v {} {} {} {:.4} {:.4} {:.4}",
            x[0],
            x[1],
            x[2],
            c[0] as f32 / 255.0,
            c[1] as f32 / 255.0,
            c[2] as f32 / 255.0
        );
    }
    for n in &mesh.normals {
        let _ = writeln!(s, "vn {} {} {}", n[0], n[1], n[2]);
    }
    if textured {
        for t in &mesh.texcoords {
            let _ = writeln!(s, "vt {} {}", t[0], 1.0 - t[1]);
        }
        let _ = writeln!(s, "usemtl rank3_texture");
    }
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| i + 1);
        if textured {
            let _ = writeln!(s, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}");
        } else {
            let _ = writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}");
        }
    }
    s
}

/// The MTL text naming `texture_name`.
pub fn mtl_text(texture_name: &str) -> String {
    format!(
        "# rank3 texture atlas\nnewmtl rank3_texture\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\n\
         map_Kd {texture_name}\n"
    )
}

fn pad4(buf: &mut Vec<u8>, byte: u8) {
    while !buf.len().is_multiple_of(4) {
        buf.push(byte);
    }
}

/// The binary glTF 2.0 bytes of the mesh (texture embedded when present).
pub fn glb_bytes(mesh: &Mesh) -> Result<Vec<u8>> {
    let n = mesh.positions.len();
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut push_view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| {
        pad4(bin, 0);
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        let mut v = json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        views.push(v);
        views.len() - 1
    };
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    let mut pos = Vec::with_capacity(12 * n);
    for x in &mesh.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(x[k]);
            hi[k] = hi[k].max(x[k]);
            pos.extend_from_slice(&x[k].to_le_bytes());
        }
    }
    if n == 0 {
        lo = [0.0; 3];
        hi = [0.0; 3];
    }
    let v_pos = push_view(&mut bin, &pos, Some(34962));
    let nrm: Vec<u8> = mesh
        .normals
        .iter()
        .flat_map(|n| n.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    let v_nrm = push_view(&mut bin, &nrm, Some(34962));
    let col: Vec<u8> = mesh
        .colors
        .iter()
        .flat_map(|c| [c[0], c[1], c[2], 255])
        .collect();
    let v_col = push_view(&mut bin, &col, Some(34962));
    let idx: Vec<u8> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.iter().flat_map(|i| i.to_le_bytes()))
        .collect();
    let v_idx = push_view(&mut bin, &idx, Some(34963));
    let mut accessors = vec![
        json!({"bufferView": v_pos, "componentType": 5126, "count": n, "type": "VEC3",
               "min": lo, "max": hi}),
        json!({"bufferView": v_col, "componentType": 5121, "normalized": true, "count": n,
               "type": "VEC4"}),
        json!({"bufferView": v_idx, "componentType": 5125, "count": 3 * mesh.triangles.len(),
               "type": "SCALAR"}),
        json!({"bufferView": v_nrm, "componentType": 5126, "count": n, "type": "VEC3"}),
    ];
    // glTF multiplies the base colour texture by COLOR_0: the colours go in only without a
    // texture.
    let mut attributes = json!({"POSITION": 0, "NORMAL": 3});
    if mesh.texture.is_none() {
        attributes["COLOR_0"] = json!(1);
    }
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": concat!("rank3 ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "rank3 mesh", "rotation": [1.0, 0.0, 0.0, 0.0]}],
    });
    let mut material = json!({
        "name": "rank3_texture",
        "doubleSided": true,
        "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
        "extensions": {"KHR_materials_unlit": {}},
    });
    if let Some(png) = texture_png(mesh)? {
        let uv: Vec<u8> = mesh
            .texcoords
            .iter()
            .flat_map(|t| t.iter().flat_map(|v| v.to_le_bytes()))
            .collect();
        let v_uv = push_view(&mut bin, &uv, Some(34962));
        accessors.push(
            json!({"bufferView": v_uv, "componentType": 5126, "count": n,
                              "type": "VEC2"}),
        );
        attributes["TEXCOORD_0"] = json!(accessors.len() - 1);
        let v_img = push_view(&mut bin, &png, None);
        doc["images"] = json!([{"bufferView": v_img, "mimeType": "image/png"}]);
        doc["textures"] = json!([{"source": 0}]);
        material["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
    }
    pad4(&mut bin, 0);
    doc["extensionsUsed"] = json!(["KHR_materials_unlit"]);
    doc["materials"] = json!([material]);
    doc["meshes"] = json!([{"primitives": [{"attributes": attributes, "indices": 2,
                                            "material": 0, "mode": 4}]}]);
    doc["accessors"] = json!(accessors);
    doc["bufferViews"] = json!(views);
    doc["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut js = serde_json::to_vec(&doc).map_err(|e| Error::Image {
        path: "mesh.glb".into(),
        message: format!("cannot encode the glTF document: {e}"),
    })?;
    pad4(&mut js, b' ');
    let total = 12 + 8 + js.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

/// Writes [`MESH_FILES`] into `dir` (the MTL and PNG only with a texture).
pub fn write_all(mesh: &Mesh, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let [obj, mtl, png, glb] = MESH_FILES;
    if let Some(bytes) = texture_png(mesh)? {
        crate::atomic::write(&dir.join(png), bytes)?;
        crate::atomic::write(&dir.join(mtl), mtl_text(png))?;
    }
    crate::atomic::write(&dir.join(obj), obj_text(mesh, mtl))?;
    crate::atomic::write(&dir.join(glb), glb_bytes(mesh)?)
}
