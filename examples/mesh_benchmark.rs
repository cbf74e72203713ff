//! The textured mesh measured: on synthetic textured scenes with a known surface (rendered by
//! `rank3::tracking::scene3d`, tracked, reconstructed and meshed as `rank3 run` does), the mean
//! distance of the mesh to the true surface after a similarity alignment, the share of
//! triangles that bridge two surfaces, and the time of each stage; on the hotel sequence
//! (when the data set is present), the mesh and texture figures and the stages' times.
//!
//! `cargo run --release --example mesh_benchmark [-- FRAMES]` (default 24 frames);
//! the hotel is read from `$RANK3_DATASETS/hotel/images`.

use std::time::Instant;

use nalgebra::Vector3;
use rank3::mesh::{MeshConfig, Scene};
use rank3::tracking::scene3d::{Scene3d, arc_cameras, write_frames};
use rank3::tracking::{FrameSource, TrackerConfig, track_source};
use rank3::{Config, Reconstruction};

struct Run {
    table: rank3::TrackTable,
    rec: Reconstruction,
    mesh: rank3::mesh::Mesh,
    seconds: [f64; 3],
}

fn run(frames: &std::path::Path, size: Option<[u32; 2]>) -> Result<Run, rank3::Error> {
    let t0 = Instant::now();
    let mut src = FrameSource::open(frames)?;
    let mut seen_size = None;
    let (table, _) = track_source(&mut src, &TrackerConfig::default(), None, &mut |_, img| {
        seen_size.get_or_insert([img.width as u32, img.height as u32]);
    })?;
    let size = size.or(seen_size);
    let t1 = Instant::now();
    // As `rank3 run`: the camera chosen from the data, the frames' size known.
    let mut config = Config {
        camera: rank3::CameraModel::Auto,
        ..Config::default()
    };
    config.perspective.intrinsics.image_size = size;
    let rec = Reconstruction::from_tracks(&table, &config)?;
    let t2 = Instant::now();
    let mesh = rank3::mesh::from_frames(&rec, &table, frames, size, &MeshConfig::default())?;
    Ok(Run {
        seconds: [
            (t1 - t0).as_secs_f64(),
            (t2 - t1).as_secs_f64(),
            t2.elapsed().as_secs_f64(),
        ],
        table,
        rec,
        mesh,
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn synthetic(
    n_frames: usize,
    panel: bool,
    half_angle: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    let size = [480u32, 360];
    let s3 = Scene3d::corner(panel);
    let target = Vector3::new(0.0, 0.0, -0.7);
    let cams = arc_cameras(n_frames, 5.0, half_angle, 0.6, target, 420.0, size);
    let dir = std::env::temp_dir().join(format!("rank3-mesh-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    write_frames(&s3, &cams, size, &dir)?;
    let r = run(&dir, Some(size))?;
    let _ = std::fs::remove_dir_all(&dir);
    let scene = Scene::from_reconstruction(&r.rec, &r.table, Some(size))?;
    // Truth of each track: its observations triangulated with the true cameras (linear,
    // then the nearest point of the true surface), kept when that point reprojects within
    // 2 px RMS of the observations and lies within 1 % of a wall's width of the surface;
    // otherwise the track slid (a false track, e.g. on a silhouette or a T-junction).
    let mut truth: Vec<Option<(Vector3<f64>, usize)>> = vec![None; r.table.n_tracks()];
    let mut false_tracks = 0usize;
    for (p, t) in truth.iter_mut().enumerate() {
        let obs: Vec<(usize, [f64; 2])> = (0..r.table.n_frames())
            .filter_map(|f| Some((f, r.table.get(f, p)?)))
            .collect();
        if obs.len() < 2 {
            false_tracks += 1;
            continue;
        }
        let mut a = nalgebra::DMatrix::<f64>::zeros(2 * obs.len(), 4);
        for (k, (f, xy)) in obs.iter().enumerate() {
            let c = &cams[*f];
            let mut pm = nalgebra::Matrix3x4::<f64>::zeros();
            pm.fixed_view_mut::<3, 3>(0, 0).copy_from(&c.r);
            pm.set_column(3, &c.t);
            let kmat = nalgebra::Matrix3::new(
                c.focal,
                0.0,
                c.principal_point[0],
                0.0,
                c.focal,
                c.principal_point[1],
                0.0,
                0.0,
                1.0,
            );
            let pm = kmat * pm;
            for (row, coord) in [(0, xy[0]), (1, xy[1])] {
                let r_ = pm.row(row) - pm.row(2) * coord;
                a.row_mut(2 * k + row).copy_from(&r_);
            }
        }
        let svd = a.svd(false, true);
        let Some(vt) = svd.v_t else { continue };
        let h = vt.row(3);
        let x = Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]);
        let (d, patch) = s3.distance_to_surface(&x);
        let rms = (obs
            .iter()
            .map(|(f, xy)| {
                cams[*f].project(&x).map_or(f64::INFINITY, |q| {
                    (q[0] - xy[0]).powi(2) + (q[1] - xy[1]).powi(2)
                })
            })
            .sum::<f64>()
            / obs.len() as f64)
            .sqrt();
        if rms < 2.0 && d < 0.02 {
            *t = Some((x, patch));
        } else {
            false_tracks += 1;
        }
    }
    let pairs: Vec<(Vector3<f64>, Vector3<f64>)> = (0..r.table.n_tracks())
        .filter(|&p| scene.inlier[p])
        .filter_map(|p| Some((scene.points[p]?, truth[p]?.0)))
        .collect();
    let (est, tru): (Vec<_>, Vec<_>) = pairs.into_iter().unzip();
    let reflect = r.rec.perspective.is_none();
    let al = rank3::eval::align_similarity(&est, &tru, reflect).ok_or("alignment failed")?;
    let map = |x: Vector3<f64>| al.rotation * x * al.scale + al.translation;
    let m = &r.mesh;
    let pos = |i: u32| {
        let p = m.positions[i as usize];
        map(Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
    };
    let mut dist = Vec::new();
    let (mut bridging, mut on_false) = (0usize, 0usize);
    for t in &m.triangles {
        let x = t.map(pos);
        for b in [
            [1.0 / 3.0; 3],
            [0.6, 0.2, 0.2],
            [0.2, 0.6, 0.2],
            [0.2, 0.2, 0.6],
        ] {
            let y = x[0] * b[0] + x[1] * b[1] + x[2] * b[2];
            dist.push(s3.distance_to_surface(&y).0);
        }
        let surf = t.map(|i| {
            truth[m.vertex_tracks[i as usize] as usize].map(|(_, p)| s3.patches[p].surface)
        });
        if surf.iter().any(|s| s.is_none()) {
            on_false += 1;
        } else if surf.iter().any(|s| *s != surf[0]) {
            bridging += 1;
        }
    }
    let mean = dist.iter().sum::<f64>() / dist.len().max(1) as f64;
    let mut sorted = dist.clone();
    sorted.sort_by(f64::total_cmp);
    let p90 = sorted
        .get(sorted.len() * 9 / 10)
        .copied()
        .unwrap_or(f64::NAN);
    let vertex_err = median(
        m.vertex_tracks
            .iter()
            .filter_map(|&p| Some(s3.distance_to_surface(&map(scene.points[p as usize]?)).0))
            .collect(),
    );
    let tex = m.report.texture.clone().unwrap_or_default();
    println!(
        "| {} | ±{half_angle}° | {} | {:?} | {} / {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {} / {} ({:.2} %) | {} | {:.1} | {:.0} % | {:.2} / {:.2} / {:.3} |",
        if panel { "corner + panel" } else { "corner" },
        n_frames,
        r.rec.camera_model,
        false_tracks,
        r.table.n_tracks(),
        m.report.surface.triangles,
        mean / 2.0 * 100.0,
        p90 / 2.0 * 100.0,
        vertex_err / 2.0 * 100.0,
        al.relative_rms * 100.0,
        bridging,
        m.triangles.len(),
        100.0 * bridging as f64 / m.triangles.len().max(1) as f64,
        on_false,
        tex.median_view_angle_deg,
        100.0 * tex.share_near_most_frontal,
        r.seconds[0],
        r.seconds[1],
        r.seconds[2],
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n_frames: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(24);
    println!("## Synthetic textured scenes ({n_frames} frames, 480×360, arc of ±25° / ±40°)\n");
    println!(
        "| scene | arc | frames | camera chosen | false tracks | triangles | mean dist (% of wall width) | p90 | vertex median | points rel. RMS (%) | bridging | on a false track | median view angle (°) | area within 5° of most frontal | track / reconstruct / mesh s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for half_angle in [25.0, 40.0] {
        for panel in [false, true] {
            eprintln!("scene panel={panel} half angle {half_angle}°");
            if let Err(e) = synthetic(n_frames, panel, half_angle) {
                println!(
                    "| {} | {n_frames} | failed: {e} |",
                    if panel { "corner + panel" } else { "corner" }
                );
            }
        }
    }
    if let Some(hotel) = rank3::datasets::find("hotel/images") {
        println!("\n## Hotel (`rank3 run hotel/images` defaults)\n");
        let r = run(&hotel, None)?;
        let m = &r.mesh;
        let s = &m.report.surface;
        let t = m.report.texture.clone().unwrap_or_default();
        println!(
            "camera {:?}; {} triangles on {} of {} tracks; reference views {:?}; dropped {:?}",
            r.rec.camera_model,
            s.triangles,
            s.vertices,
            s.eligible_tracks,
            s.reference_views
                .iter()
                .map(|v| format!("{} ({} new, {} kept)", v.frame, v.new_vertices, v.kept))
                .collect::<Vec<_>>(),
            s.dropped
        );
        println!(
            "texture: {} charts from {} frames, atlas {}×{} px; median view angle {:.1}°, {:.1} % of the area within 30° of frontal, {:.1} % within 5° of its most frontal view (median excess {:.2}°)",
            t.charts,
            t.views_used,
            t.atlas_px[0],
            t.atlas_px[1],
            t.median_view_angle_deg,
            100.0 * t.share_within_30deg,
            100.0 * t.share_near_most_frontal,
            t.median_excess_angle_deg
        );
        println!(
            "time: tracking {:.3} s, reconstruction {:.3} s, mesh {:.3} s (triangulation {:.4} s, texture {:.3} s)",
            r.seconds[0],
            r.seconds[1],
            r.seconds[2],
            m.report.seconds_surface,
            m.report.seconds_texture
        );
    }
    Ok(())
}
