//! Mesh and texture against synthetic scenes with a known surface.

use std::collections::HashMap;

use image::RgbImage;
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use super::*;
use crate::tracking::scene3d::{Patch, Pinhole, Scene3d};

const SIZE: [u32; 2] = [320, 240];

fn camera(centre: [f64; 3], focal: f64) -> Pinhole {
    Pinhole::look_at(
        Vector3::from(centre),
        Vector3::zeros(),
        Vector3::new(0.0, -1.0, 0.0),
        focal,
        [SIZE[0] as f64 / 2.0, SIZE[1] as f64 / 2.0],
    )
}

/// Jittered grid of `nu × nv` points on patch `p`.
fn grid_points(s: &Scene3d, p: usize, nu: usize, nv: usize, rng: &mut StdRng) -> Vec<Vector3<f64>> {
    let q = &s.patches[p];
    let mut out = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let a = (i as f64 + 0.5 + rng.random_range(-0.3..0.3)) / nu as f64;
            let b = (j as f64 + 0.5 + rng.random_range(-0.3..0.3)) / nv as f64;
            out.push(q.origin + q.u * a + q.v * b);
        }
    }
    out
}

/// The mesh scene of true cameras and points; a point is observed where the ray to it hits
/// it first (occlusion), inside the image.
fn scene_of(s: &Scene3d, cams: &[Pinhole], points: &[Vector3<f64>], inlier: &[bool]) -> Scene {
    let observations = cams
        .iter()
        .map(|c| {
            let o = c.centre();
            points
                .iter()
                .enumerate()
                .filter_map(|(p, x)| {
                    let xy = c.project(x)?;
                    let inside = xy[0] >= 0.0
                        && xy[1] >= 0.0
                        && xy[0] <= (SIZE[0] - 1) as f64
                        && xy[1] <= (SIZE[1] - 1) as f64;
                    let d = x - o;
                    let seen = s
                        .hit(&o, &d)
                        .is_some_and(|h| (h.distance - 1.0).abs() < 1e-6);
                    (inside && seen).then_some((p as u32, xy))
                })
                .collect()
        })
        .collect();
    Scene {
        frame_ids: (0..cams.len()).map(Id::from).collect(),
        views: cams
            .iter()
            .map(|c| {
                Some(View::Perspective {
                    r: c.r,
                    t: c.t,
                    focal: c.focal,
                    principal_point: c.principal_point,
                    k1: 0.0,
                    aspect: 1.0,
                })
            })
            .collect(),
        points: points.iter().map(|x| Some(*x)).collect(),
        inlier: inlier.to_vec(),
        homogeneous: vec![None; points.len()],
        observations,
        image_size: Some(SIZE),
    }
}

fn textured(scene: &Scene, s: &Scene3d, cams: &[Pinhole]) -> Mesh {
    let frames: Vec<RgbImage> = cams.iter().map(|c| s.render(c, SIZE[0], SIZE[1])).collect();
    let mut k = 0;
    let mut feed = || {
        k += 1;
        Ok(frames.get(k - 1).map(|f| (Id::from(k - 1), f.clone())))
    };
    build(scene, &MeshConfig::default(), Some(&mut feed)).unwrap()
}

fn plane() -> Scene3d {
    Scene3d {
        patches: vec![Patch {
            origin: Vector3::new(-1.0, -0.75, 0.0),
            u: Vector3::new(2.0, 0.0, 0.0),
            v: Vector3::new(0.0, 1.5, 0.0),
            surface: 0,
            seed: 7,
            tint: [1.0, 0.9, 0.7],
        }],
        texture_scale: 0.35,
        background: [20, 20, 20],
    }
}

/// Convex hull area of 2D points (monotone chain).
fn hull_area(mut pts: Vec<[f64; 2]>) -> f64 {
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(pts.iter())
        } else {
            Box::new(pts.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    let n = hull.len();
    (0..n)
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % n]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum::<f64>()
        .abs()
        / 2.0
}

#[test]
fn planar_scene_is_meshed_without_holes_and_its_texture_reproduces_the_source() {
    let s = plane();
    let cams = [
        camera([0.0, 0.0, -4.0], 500.0),
        camera([1.0, 0.3, -3.8], 500.0),
        camera([-1.0, -0.2, -3.8], 500.0),
    ];
    let mut rng = StdRng::seed_from_u64(3);
    let points = grid_points(&s, 0, 12, 9, &mut rng);
    let mut inlier = vec![true; points.len()];
    // Outlier tracks: flagged by the reconstruction, never vertices.
    for p in [5, 40, 77] {
        inlier[p] = false;
    }
    let scene = scene_of(&s, &cams, &points, &inlier);
    let mesh = textured(&scene, &s, &cams);
    assert!(mesh.vertex_tracks.iter().all(|&p| inlier[p as usize]));
    let used: std::collections::HashSet<u32> = mesh.vertex_tracks.iter().copied().collect();
    assert_eq!(
        used.len(),
        inlier.iter().filter(|&&i| i).count(),
        "every inlier is a vertex"
    );

    // No holes: a disc (V − E + F = 1, every edge in at most two triangles, one boundary loop).
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for t in &mesh.triangles {
        let tr = t.map(|i| mesh.vertex_tracks[i as usize]);
        for e in 0..3 {
            let (a, b) = (tr[e], tr[(e + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(edges.values().all(|&n| n <= 2), "non-manifold edge");
    let (v, e, f) = (
        used.len() as i64,
        edges.len() as i64,
        mesh.triangles.len() as i64,
    );
    assert_eq!(
        v - e + f,
        1,
        "the mesh of a plane is a disc: V − E + F = {}",
        v - e + f
    );
    let area: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let x = t.map(|i| {
                let p = mesh.positions[i as usize];
                Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
            });
            (x[1] - x[0]).cross(&(x[2] - x[0])).norm() / 2.0
        })
        .sum();
    let hull = hull_area(
        points
            .iter()
            .zip(&inlier)
            .filter(|(_, i)| **i)
            .map(|(x, _)| [x[0], x[1]])
            .collect(),
    );
    assert!(
        area > 0.97 * hull,
        "mesh area {area:.4} of the hull's {hull:.4}"
    );

    // The texture reproduces the plane's colours at points inside every triangle.
    let atlas = mesh.texture.as_ref().unwrap();
    let (mut err, mut shuffled, mut n) = (0.0, 0.0, 0.0);
    let mut samples = Vec::new();
    for t in &mesh.triangles {
        for b in [
            [0.6, 0.2, 0.2],
            [0.2, 0.6, 0.2],
            [0.2, 0.2, 0.6],
            [1.0 / 3.0; 3],
        ] {
            let x: Vector3<f64> = (0..3)
                .map(|k| {
                    let p = mesh.positions[t[k] as usize];
                    Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64) * b[k]
                })
                .sum();
            let uv: [f64; 2] = std::array::from_fn(|c| {
                (0..3)
                    .map(|k| mesh.texcoords[t[k] as usize][c] as f64 * b[k])
                    .sum()
            });
            let truth = s.color(0, (x[0] + 1.0) / 2.0, (x[1] + 0.75) / 1.5);
            let got = texture::sample(
                atlas,
                uv[0] * atlas.width() as f64 - 0.5,
                uv[1] * atlas.height() as f64 - 0.5,
            );
            samples.push((truth, got));
        }
    }
    for i in 0..samples.len() {
        let (truth, got) = samples[i];
        let other = samples[(i + samples.len() / 2) % samples.len()].1;
        for c in 0..3 {
            err += (truth[c] - got[c]).abs() / 255.0;
            shuffled += (truth[c] - other[c]).abs() / 255.0;
        }
        n += 3.0;
    }
    let (err, shuffled) = (err / n, shuffled / n);
    eprintln!(
        "texture error {err:.4}, shuffled {shuffled:.4}; area {area:.4} of hull {hull:.4}; {:?}",
        mesh.report
    );
    assert!(
        err < 0.03,
        "texture error {err:.4} (shuffled {shuffled:.4})"
    );
    assert!(
        shuffled > 4.0 * err,
        "texture error {err:.4} vs shuffled {shuffled:.4}"
    );
    // Per-track colours are the frames' colours at the observations.
    let c = mesh.track_colors[0].unwrap();
    let x = points[0];
    let truth = s.color(0, (x[0] + 1.0) / 2.0, (x[1] + 0.75) / 1.5);
    assert!(
        (0..3).all(|k| (c[k] as f64 - truth[k]).abs() < 20.0),
        "{c:?} vs {truth:?}"
    );
}

#[test]
fn no_triangle_bridges_a_panel_and_the_wall_behind_it() {
    let s = Scene3d {
        patches: vec![
            Patch {
                origin: Vector3::new(-1.5, -1.0, 0.0),
                u: Vector3::new(3.0, 0.0, 0.0),
                v: Vector3::new(0.0, 2.0, 0.0),
                surface: 0,
                seed: 1,
                tint: [0.9, 0.9, 1.0],
            },
            Patch {
                origin: Vector3::new(-0.5, -0.4, -1.2),
                u: Vector3::new(1.0, 0.0, 0.0),
                v: Vector3::new(0.0, 0.8, 0.0),
                surface: 1,
                seed: 2,
                tint: [1.0, 0.7, 0.5],
            },
        ],
        texture_scale: 0.3,
        background: [20, 20, 20],
    };
    let cams: Vec<Pinhole> = (0..5)
        .map(|k| camera([-1.2 + 0.6 * k as f64, 0.2, -6.0], 420.0))
        .collect();
    let mut rng = StdRng::seed_from_u64(5);
    let mut points = grid_points(&s, 0, 18, 12, &mut rng);
    let n_wall = points.len();
    points.extend(grid_points(&s, 1, 7, 6, &mut rng));
    let surface = |p: u32| usize::from(p as usize >= n_wall);
    let scene = scene_of(&s, &cams, &points, &vec![true; points.len()]);
    let mesh = textured(&scene, &s, &cams);
    let tris: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| mesh.vertex_tracks[i as usize]))
        .collect();
    let bridging = tris
        .iter()
        .filter(|t| t.iter().any(|&p| surface(p) != surface(t[0])))
        .count();
    let on = |k: usize| {
        tris.iter()
            .filter(|t| t.iter().all(|&p| surface(p) == k))
            .count()
    };
    eprintln!(
        "wall {} panel {} bridging {bridging} of {}; {:?}",
        on(0),
        on(1),
        tris.len(),
        mesh.report.surface
    );
    assert!(
        on(0) > 200 && on(1) > 30,
        "wall {} / panel {} triangles",
        on(0),
        on(1)
    );
    assert!(
        bridging * 100 <= tris.len(),
        "{bridging} of {} triangles bridge the panel and the wall ({:?})",
        tris.len(),
        mesh.report.surface.dropped
    );
}

#[test]
fn exports_hold_every_vertex_triangle_and_the_texture() {
    let s = plane();
    let cams = [
        camera([0.0, 0.0, -4.0], 500.0),
        camera([0.8, 0.0, -3.9], 500.0),
    ];
    let mut rng = StdRng::seed_from_u64(9);
    let points = grid_points(&s, 0, 6, 5, &mut rng);
    let scene = scene_of(&s, &cams, &points, &vec![true; points.len()]);
    let mesh = textured(&scene, &s, &cams);
    let obj = export::obj_text(&mesh, "mesh.mtl");
    let count = |prefix: &str| obj.lines().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("v "), mesh.positions.len());
    assert_eq!(count("vt "), mesh.positions.len());
    assert_eq!(count("vn "), mesh.positions.len());
    assert_eq!(count("f "), mesh.triangles.len());
    let glb = export::glb_bytes(&mesh).unwrap();
    assert_eq!(&glb[0..4], b"glTF");
    let u32_at = |i: usize| u32::from_le_bytes(glb[i..i + 4].try_into().unwrap()) as usize;
    assert_eq!(u32_at(4), 2);
    assert_eq!(u32_at(8), glb.len());
    let json_len = u32_at(12);
    assert_eq!(&glb[16..20], b"JSON");
    let doc: serde_json::Value = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin_len = u32_at(20 + json_len);
    assert_eq!(&glb[24 + json_len..28 + json_len], b"BIN\0");
    assert_eq!(doc["buffers"][0]["byteLength"], bin_len);
    assert_eq!(doc["accessors"][0]["count"], mesh.positions.len());
    assert_eq!(doc["accessors"][2]["count"], 3 * mesh.triangles.len());
    let img = &doc["images"][0];
    let view = &doc["bufferViews"][img["bufferView"].as_u64().unwrap() as usize];
    let start = 28 + json_len + view["byteOffset"].as_u64().unwrap() as usize;
    assert_eq!(&glb[start + 1..start + 4], b"PNG");
    // Without frames: geometry and grey colours, no texture.
    let bare = build(&scene, &MeshConfig::default(), None).unwrap();
    assert!(bare.texture.is_none() && bare.texcoords.is_empty());
    assert_eq!(bare.triangles.len(), mesh.triangles.len());
}

#[test]
fn invalid_settings_are_errors() {
    for cfg in [
        MeshConfig {
            max_edge_ratio: 0.5,
            ..Default::default()
        },
        MeshConfig {
            min_view_cos: 1.5,
            ..Default::default()
        },
        MeshConfig {
            max_reference_views: 0,
            ..Default::default()
        },
    ] {
        assert!(matches!(cfg.validate(), Err(Error::InvalidConfig { .. })));
    }
}
