//! Synthetic image sequences of textured 3D scenes with a known surface, for testing and
//! measuring the mesh and texture stages (and the tracker under real parallax).
//!
//! A scene is a set of textured planar rectangles ([`Patch`]: `X(a, b) = o + a·u + b·v`,
//! `a, b ∈ [0, 1]`), each belonging to a *surface* (patches of one surface meet along edges,
//! e.g. two walls of a box; different surfaces are separated by a depth discontinuity). Their
//! colour is a seeded multi-octave value noise of the patch coordinates in world units under
//! a scatter of sharp-edged squares and discs, tinted per patch. Frames are rendered by casting one ray per pixel through a pinhole
//! camera ([`Pinhole`], `x = f·(X_c/Z_c) + c`, `X_c = R X + t`) and taking the nearest hit;
//! pixels that hit nothing are the flat background colour (no texture, so no tracks).
//!
//! Complexity: O(W·H·patches) per frame.

use image::{Rgb, RgbImage};
use nalgebra::{Matrix3, Vector3};

/// A textured rectangle `X(a, b) = origin + a·u + b·v`.
#[derive(Debug, Clone)]
pub struct Patch {
    pub origin: Vector3<f64>,
    pub u: Vector3<f64>,
    pub v: Vector3<f64>,
    /// Index of the surface it belongs to.
    pub surface: usize,
    pub seed: u64,
    /// Multiplies the grey texture.
    pub tint: [f64; 3],
}

/// A pinhole camera, `x = focal · (X_c / Z_c) + principal_point`, `X_c = R X + t`.
#[derive(Debug, Clone)]
pub struct Pinhole {
    pub r: Matrix3<f64>,
    pub t: Vector3<f64>,
    pub focal: f64,
    pub principal_point: [f64; 2],
}

impl Pinhole {
    /// A camera at `centre` looking at `target`, image y axis along `−up` (y down).
    pub fn look_at(
        centre: Vector3<f64>,
        target: Vector3<f64>,
        up: Vector3<f64>,
        focal: f64,
        principal_point: [f64; 2],
    ) -> Pinhole {
        let z = (target - centre).normalize();
        let x = z.cross(&up).normalize();
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        Pinhole {
            t: -(r * centre),
            r,
            focal,
            principal_point,
        }
    }

    /// Camera centre `−Rᵀ t`.
    pub fn centre(&self) -> Vector3<f64> {
        -(self.r.transpose() * self.t)
    }

    /// Image position of `x` (`None` behind the camera).
    pub fn project(&self, x: &Vector3<f64>) -> Option<[f64; 2]> {
        let c = self.r * x + self.t;
        (c[2] > 1e-12).then(|| {
            [
                self.focal * c[0] / c[2] + self.principal_point[0],
                self.focal * c[1] / c[2] + self.principal_point[1],
            ]
        })
    }

    /// World direction of the ray through pixel `(x, y)`.
    pub fn ray(&self, x: f64, y: f64) -> Vector3<f64> {
        let d = Vector3::new(
            (x - self.principal_point[0]) / self.focal,
            (y - self.principal_point[1]) / self.focal,
            1.0,
        );
        self.r.transpose() * d
    }
}

/// A hit of a ray on a patch.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    pub distance: f64,
    pub patch: usize,
    pub a: f64,
    pub b: f64,
}

/// Textured patches and the scale of their texture.
#[derive(Debug, Clone)]
pub struct Scene3d {
    pub patches: Vec<Patch>,
    /// World size of the texture's coarsest octave.
    pub texture_scale: f64,
    pub background: [u8; 3],
}

fn hash(seed: u64, i: i64, j: i64) -> f64 {
    let mut h = seed
        ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    h = h.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let (i, j) = (x0 as i64, y0 as i64);
    let a = hash(seed, i, j);
    let b = hash(seed, i + 1, j);
    let c = hash(seed, i, j + 1);
    let d = hash(seed, i + 1, j + 1);
    (a * (1.0 - sx) + b * sx) * (1.0 - sy) + (c * (1.0 - sx) + d * sx) * sy
}

impl Scene3d {
    /// The texture's grey level at patch coordinates (world units along `u` and `v`), in
    /// `[0, 1]`: three octaves of value noise under a scatter of sharp-edged squares and discs
    /// (one per cell of half the texture scale; their corners and edges are what a tracker
    /// locks on).
    pub fn texture(&self, patch: usize, su: f64, sv: f64) -> f64 {
        let seed = self.patches[patch].seed;
        let mut v = 0.0;
        let mut amp = 0.5;
        let mut freq = 1.0 / self.texture_scale;
        for o in 0..3u64 {
            v += amp * value_noise(seed.wrapping_add(o * 7919), su * freq, sv * freq);
            amp *= 0.5;
            freq *= 2.0;
        }
        let noise = (v / 0.875).clamp(0.0, 1.0);
        let cell = 0.5 * self.texture_scale;
        let (ci, cj) = ((su / cell).floor(), (sv / cell).floor());
        let h = |k: u64| hash(seed.wrapping_add(k * 104_729), ci as i64, cj as i64);
        let (cx, cy) = (
            (ci + 0.3 + 0.4 * h(1)) * cell,
            (cj + 0.3 + 0.4 * h(2)) * cell,
        );
        let r = (0.12 + 0.14 * h(3)) * cell;
        let (dx, dy) = (su - cx, sv - cy);
        let inside = if h(4) < 0.5 {
            dx.abs() < r && dy.abs() < r
        } else {
            dx * dx + dy * dy < r * r
        };
        if inside {
            let level = h(5);
            if level < 0.5 {
                0.05 + 0.2 * level
            } else {
                0.75 + 0.25 * level
            }
        } else {
            0.25 + 0.5 * noise
        }
    }

    /// RGB (`[0, 255]`) of patch `p` at `(a, b)`.
    pub fn color(&self, p: usize, a: f64, b: f64) -> [f64; 3] {
        let q = &self.patches[p];
        let g = self.texture(p, a * q.u.norm(), b * q.v.norm());
        q.tint
            .map(|t| (255.0 * (0.1 + 0.85 * g) * t).clamp(0.0, 255.0))
    }

    /// The nearest patch hit by the ray `o + s·d`, `s > 0`.
    pub fn hit(&self, o: &Vector3<f64>, d: &Vector3<f64>) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for (i, q) in self.patches.iter().enumerate() {
            let n = q.u.cross(&q.v);
            let den = n.dot(d);
            if den.abs() < 1e-15 {
                continue;
            }
            let s = n.dot(&(q.origin - o)) / den;
            if s <= 1e-9 || best.is_some_and(|b| b.distance <= s) {
                continue;
            }
            let x = o + d * s - q.origin;
            // Solve x = a u + b v in the patch plane.
            let (uu, uv, vv) = (q.u.dot(&q.u), q.u.dot(&q.v), q.v.dot(&q.v));
            let (xu, xv) = (x.dot(&q.u), x.dot(&q.v));
            let det = uu * vv - uv * uv;
            let a = (xu * vv - xv * uv) / det;
            let b = (xv * uu - xu * uv) / det;
            if (0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b) {
                best = Some(Hit {
                    distance: s,
                    patch: i,
                    a,
                    b,
                });
            }
        }
        best
    }

    /// The point seen at pixel `(x, y)` of `cam`, and its patch.
    pub fn point_at(&self, cam: &Pinhole, x: f64, y: f64) -> Option<(Vector3<f64>, usize)> {
        let o = cam.centre();
        let d = cam.ray(x, y);
        self.hit(&o, &d).map(|h| (o + d * h.distance, h.patch))
    }

    /// Renders `cam`'s `width × height` image (one ray per pixel centre, 2×2 supersampled).
    pub fn render(&self, cam: &Pinhole, width: u32, height: u32) -> RgbImage {
        let o = cam.centre();
        RgbImage::from_fn(width, height, |x, y| {
            let mut acc = [0.0; 3];
            for (dx, dy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                let d = cam.ray(x as f64 + dx, y as f64 + dy);
                let c = match self.hit(&o, &d) {
                    Some(h) => self.color(h.patch, h.a, h.b),
                    None => self.background.map(f64::from),
                };
                for k in 0..3 {
                    acc[k] += c[k] / 4.0;
                }
            }
            Rgb(acc.map(|c| c.round().clamp(0.0, 255.0) as u8))
        })
    }
}

impl Scene3d {
    /// Two textured walls meeting at a right angle in a vertical edge that points towards the
    /// cameras (as the hotel's), 2 units high, each 2 units wide; with `panel`, a smaller
    /// panel floating 1 unit in front of the edge (a second surface, so a depth
    /// discontinuity).
    pub fn corner(panel: bool) -> Scene3d {
        let s = std::f64::consts::FRAC_1_SQRT_2 * 2.0;
        let mut patches = vec![
            Patch {
                origin: Vector3::new(-s, -1.0, 0.0),
                u: Vector3::new(s, 0.0, -s),
                v: Vector3::new(0.0, 2.0, 0.0),
                surface: 0,
                seed: 11,
                tint: [1.0, 0.92, 0.8],
            },
            Patch {
                origin: Vector3::new(0.0, -1.0, -s),
                u: Vector3::new(s, 0.0, s),
                v: Vector3::new(0.0, 2.0, 0.0),
                surface: 0,
                seed: 12,
                tint: [0.8, 0.9, 1.0],
            },
        ];
        if panel {
            patches.push(Patch {
                origin: Vector3::new(-0.45, -0.35, -s - 1.0),
                u: Vector3::new(0.9, 0.0, 0.0),
                v: Vector3::new(0.0, 0.7, 0.0),
                surface: 1,
                seed: 13,
                tint: [1.0, 0.75, 0.6],
            });
        }
        Scene3d {
            patches,
            texture_scale: 0.3,
            background: [25, 25, 25],
        }
    }

    /// Distance from `x` to the nearest patch (the true surface), and that patch.
    pub fn distance_to_surface(&self, x: &Vector3<f64>) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0);
        for (i, q) in self.patches.iter().enumerate() {
            // Closest point of the rectangle: clamp the plane coordinates.
            let d = x - q.origin;
            let (uu, uv, vv) = (q.u.dot(&q.u), q.u.dot(&q.v), q.v.dot(&q.v));
            let (xu, xv) = (d.dot(&q.u), d.dot(&q.v));
            let det = uu * vv - uv * uv;
            let a = ((xu * vv - xv * uv) / det).clamp(0.0, 1.0);
            let b = ((xv * uu - xu * uv) / det).clamp(0.0, 1.0);
            let dist = (x - (q.origin + q.u * a + q.v * b)).norm();
            if dist < best.0 {
                best = (dist, i);
            }
        }
        best
    }
}

/// `n` cameras on a horizontal arc of radius `radius` about the y axis through `target`,
/// from `−half_angle_deg` to `+half_angle_deg` (0° looks along +z), `height` above it (image
/// y down, so "above" is −y), principal point at the centre of a `size` image.
pub fn arc_cameras(
    n: usize,
    radius: f64,
    half_angle_deg: f64,
    height: f64,
    target: Vector3<f64>,
    focal: f64,
    size: [u32; 2],
) -> Vec<Pinhole> {
    (0..n)
        .map(|k| {
            let t = if n > 1 {
                -1.0 + 2.0 * k as f64 / (n - 1) as f64
            } else {
                0.0
            };
            let a = (t * half_angle_deg).to_radians();
            let centre = target + Vector3::new(radius * a.sin(), -height, -radius * a.cos());
            Pinhole::look_at(
                centre,
                target,
                Vector3::new(0.0, -1.0, 0.0),
                focal,
                [size[0] as f64 / 2.0, size[1] as f64 / 2.0],
            )
        })
        .collect()
}

/// Renders every camera's frame into `dir` as `frame_000.png`, … (created if needed).
pub fn write_frames(
    scene: &Scene3d,
    cams: &[Pinhole],
    size: [u32; 2],
    dir: &std::path::Path,
) -> crate::Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| crate::Error::io(dir, e))?;
    for (k, c) in cams.iter().enumerate() {
        let path = dir.join(format!("frame_{k:03}.png"));
        scene
            .render(c, size[0], size[1])
            .save(&path)
            .map_err(|e| crate::Error::Image {
                path: path.clone(),
                message: format!("cannot write PNG: {e}"),
            })?;
    }
    Ok(())
}
