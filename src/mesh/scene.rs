//! The cameras, points and observations a mesh is built on: one projection abstraction over
//! every camera model rank3 has.
//!
//! * Affine family (orthographic, scaled orthographic): `[x, y] = s·[i; j]·X + t`; the camera
//!   looks along `k = i × j`. Depth order along `k` is ambiguous (the Necker reversal of the
//!   affine reconstruction), so no test here relies on which side is in front.
//! * Perspective: `x_c = R X + t`, `[x, y] = f·d·(x_c/z_c, y_c/z_c) + c`, `d = 1 + k₁ r²`
//!   (the model of [`crate::perspective`]); depth `z_c` is meaningful.
//! * Projective: `w ≃ P X̃` with `X̃` the track's homogeneous point; the mesh's 3D positions and
//!   the viewing directions come from the affine-family model fitted on the way (a projective
//!   reconstruction has no angles), the image positions from `P`.

use std::collections::HashMap;

use nalgebra::{Matrix3, Matrix3x4, Vector3, Vector4};

use crate::reconstruction::Reconstruction;
use crate::table::Id;
use crate::{Error, Result, TrackTable};

/// One frame's camera.
#[derive(Debug, Clone)]
pub enum View {
    Affine {
        /// `aspect·s·i` and `s·j`.
        rows: [Vector3<f64>; 2],
        t: [f64; 2],
        /// The viewing direction `k = i × j` (unit).
        k: Vector3<f64>,
    },
    Perspective {
        r: Matrix3<f64>,
        t: Vector3<f64>,
        /// Focal length along y, pixels (along x: `aspect · focal`).
        focal: f64,
        principal_point: [f64; 2],
        k1: f64,
        /// Aspect ratio `f_x / f_y` of the pixels.
        aspect: f64,
    },
    Projective {
        p: Matrix3x4<f64>,
        /// Viewing direction of the affine-family model of the same frame (unit).
        k: Vector3<f64>,
    },
}

/// Points, cameras and observations, indexed like the input table (frame `f`, track `p`).
#[derive(Debug, Clone)]
pub struct Scene {
    pub frame_ids: Vec<Id>,
    /// The camera of each input frame (`None`: the frame was not used).
    pub views: Vec<Option<View>>,
    /// The 3D point of each input track (`None`: not reconstructed).
    pub points: Vec<Option<Vector3<f64>>>,
    /// False for outlier tracks: they are coloured but never become mesh vertices.
    pub inlier: Vec<bool>,
    /// Homogeneous points of the projective model (projective views only).
    pub homogeneous: Vec<Option<Vector4<f64>>>,
    /// Observations per frame: `(track, [x, y])`, track ascending (without the entries the
    /// robust pass flagged as gross errors).
    pub observations: Vec<Vec<(u32, [f64; 2])>>,
    /// Width and height of the frames, pixels, when known.
    pub image_size: Option<[u32; 2]>,
}

impl Scene {
    /// The scene of a reconstruction of `table` (the table it was computed from): the
    /// perspective model when there is one, else the projective one for the image positions
    /// (with the affine-family structure), else the affine-family model.
    pub fn from_reconstruction(
        rec: &Reconstruction,
        table: &TrackTable,
        image_size: Option<[u32; 2]>,
    ) -> Result<Scene> {
        let (nf, nt) = (table.n_frames(), table.n_tracks());
        let frame_index: HashMap<&Id, usize> = table
            .frame_ids()
            .iter()
            .enumerate()
            .map(|(i, id)| (id, i))
            .collect();
        let track_index: HashMap<&Id, usize> = table
            .track_ids()
            .iter()
            .enumerate()
            .map(|(i, id)| (id, i))
            .collect();
        let lookup = |map: &HashMap<&Id, usize>, id: &Id, what: &'static str| {
            map.get(id).copied().ok_or_else(|| Error::InvalidConfig {
                field: what,
                message: format!("{what} {id} of the reconstruction is not in the track table"),
            })
        };
        let mut views: Vec<Option<View>> = vec![None; nf];
        let mut points = vec![None; nt];
        let mut inlier = vec![false; nt];
        let mut homogeneous = vec![None; nt];
        let axis = |r: &[[f64; 3]; 3], row: usize| Vector3::new(r[row][0], r[row][1], r[row][2]);
        if let Some(per) = &rec.perspective {
            for c in &per.cameras {
                let f = lookup(&frame_index, &c.frame, "frame")?;
                views[f] = Some(View::Perspective {
                    r: Matrix3::from_fn(|a, b| c.rotation[a][b]),
                    t: Vector3::from(c.translation),
                    focal: c.focal_px,
                    principal_point: per.intrinsics.principal_point,
                    k1: per.intrinsics.k1,
                    aspect: per.intrinsics.aspect_ratio,
                });
            }
            for q in &per.points {
                let p = lookup(&track_index, &q.track, "track")?;
                points[p] = Some(Vector3::from(q.xyz)).filter(|x| x.iter().all(|v| v.is_finite()));
                inlier[p] = q.inlier;
            }
        } else {
            let mut k_of = HashMap::new();
            for c in &rec.frames {
                let f = lookup(&frame_index, &c.frame, "frame")?;
                let (i, j) = (axis(&c.rotation, 0), axis(&c.rotation, 1));
                let k = i.cross(&j).normalize();
                k_of.insert(f, k);
                views[f] = Some(View::Affine {
                    rows: [i * (c.scale * rec.aspect_ratio), j * c.scale],
                    t: c.translation,
                    k,
                });
            }
            for q in &rec.points {
                let p = lookup(&track_index, &q.track, "track")?;
                points[p] = Some(Vector3::from(q.xyz)).filter(|x| x.iter().all(|v| v.is_finite()));
                inlier[p] = q.inlier;
            }
            if let Some(proj) = &rec.projective {
                let mut pviews: Vec<Option<View>> = vec![None; nf];
                for c in &proj.cameras {
                    let f = lookup(&frame_index, &c.frame, "frame")?;
                    if let Some(&k) = k_of.get(&f) {
                        pviews[f] = Some(View::Projective {
                            p: Matrix3x4::from_fn(|a, b| c.p[a][b]),
                            k,
                        });
                    }
                }
                views = pviews;
                for q in &proj.points {
                    let p = lookup(&track_index, &q.track, "track")?;
                    homogeneous[p] =
                        Some(Vector4::from(q.x)).filter(|x| x.iter().all(|v| v.is_finite()));
                    inlier[p] &= q.inlier;
                }
                for p in 0..nt {
                    if homogeneous[p].is_none() {
                        points[p] = None;
                    }
                }
            }
        }
        // Entries the robust pass flagged as gross errors are not observations of their track.
        let flagged: std::collections::HashSet<(usize, usize)> =
            rec.robust.as_ref().map_or_else(Default::default, |r| {
                r.flagged_indices.iter().copied().collect()
            });
        let mut observations = vec![Vec::new(); nf];
        for (f, obs) in observations.iter_mut().enumerate() {
            for p in 0..nt {
                if let Some(xy) = table.get(f, p)
                    && !flagged.contains(&(f, p))
                {
                    obs.push((p as u32, xy));
                }
            }
        }
        Ok(Scene {
            frame_ids: table.frame_ids().to_vec(),
            views,
            points,
            inlier,
            homogeneous,
            observations,
            image_size,
        })
    }

    /// Number of input frames.
    pub fn n_frames(&self) -> usize {
        self.views.len()
    }

    /// Number of input tracks.
    pub fn n_tracks(&self) -> usize {
        self.points.len()
    }

    /// Image position of track `p` in frame `f` by the model (`None` without a camera or a
    /// point, or behind a perspective camera).
    pub fn project(&self, f: usize, p: usize) -> Option<[f64; 2]> {
        let view = self.views.get(f)?.as_ref()?;
        match view {
            View::Projective { p: pm, .. } => {
                let x = pm * self.homogeneous.get(p)?.as_ref()?;
                (x[2].abs() > 1e-300).then(|| [x[0] / x[2], x[1] / x[2]])
            }
            _ => self.project_point(f, self.points.get(p)?.as_ref()?),
        }
    }

    /// Image position of a 3D point in frame `f` (affine-family and perspective views).
    pub fn project_point(&self, f: usize, x: &Vector3<f64>) -> Option<[f64; 2]> {
        match self.views.get(f)?.as_ref()? {
            View::Affine { rows, t, .. } => Some([rows[0].dot(x) + t[0], rows[1].dot(x) + t[1]]),
            View::Perspective {
                r,
                t,
                focal,
                principal_point: c,
                k1,
                aspect,
            } => {
                let xc = r * x + t;
                if xc[2] <= 0.0 {
                    return None;
                }
                let (nx, ny) = (xc[0] / xc[2], xc[1] / xc[2]);
                let d = 1.0 + k1 * (nx * nx + ny * ny);
                Some([aspect * focal * d * nx + c[0], focal * d * ny + c[1]])
            }
            View::Projective { .. } => None,
        }
    }

    /// Unit direction from `x` towards the camera of frame `f` (for affine-family views the
    /// viewing axis, sign arbitrary).
    pub fn toward_camera(&self, f: usize, x: &Vector3<f64>) -> Option<Vector3<f64>> {
        match self.views.get(f)?.as_ref()? {
            View::Affine { k, .. } | View::Projective { k, .. } => Some(-k),
            View::Perspective { r, t, .. } => {
                let c = -(r.transpose() * t);
                (c - x).try_normalize(1e-300)
            }
        }
    }

    /// Depth of `x` in front of the camera of frame `f`: perspective views only (the only
    /// model whose depth order is known).
    pub fn depth(&self, f: usize, x: &Vector3<f64>) -> Option<f64> {
        match self.views.get(f)?.as_ref()? {
            View::Perspective { r, t, .. } => Some((r * x + t)[2]),
            _ => None,
        }
    }

    /// True when the views' depth order is known (perspective).
    pub fn has_depth(&self) -> bool {
        self.views
            .iter()
            .flatten()
            .any(|v| matches!(v, View::Perspective { .. }))
    }
}
