use rerun::RecordingStream;

use super::{RecordingResult, TIMELINE_FRAME, TIMELINE_STAGE, paths};

/// Which parts of the viewer layout [`send_layout`] shows (views of absent data would sit
/// empty).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LayoutParts {
    /// Frames and tracker counts (`rank3 track`, `rank3 run`).
    pub tracking: bool,
    /// A reconstruction: metric and affine structure, W, spectra, solvers, summary.
    pub reconstruction: bool,
    /// Synthetic ground truth (`rank3 synth`).
    pub truth: bool,
    /// A perspective reconstruction: its Euclidean structure and frustums beside the
    /// affine-model structure.
    pub perspective: bool,
    /// Several objects (`--objects`): each object's structure and cameras in one 3D view.
    pub objects: bool,
}

/// Where a 3D view's eye starts: a position looking at a target, with an up direction, all
/// in the coordinates of the view's origin entity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Eye {
    pub position: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
}

/// What [`send_layout`] last sent to a recording, and the eyes that frame its 3D views
/// ([`frame_view`]), so that the layout can be sent again once the points are known.
struct Sent {
    recording: String,
    parts: Option<LayoutParts>,
    /// (view origin, eye).
    eyes: Vec<(String, Eye)>,
}

static SENT: std::sync::Mutex<Vec<Sent>> = std::sync::Mutex::new(Vec::new());

/// The key of `rec` in [`SENT`]: its recording id (`None` for a disabled stream).
fn recording_key(rec: &RecordingStream) -> Option<String> {
    rec.store_info()
        .map(|info| info.recording_id().as_str().to_string())
}

/// Forgets what was sent to `rec` (called when the recording is finished).
pub(super) fn forget(rec: &RecordingStream) {
    if let (Some(key), Ok(mut sent)) = (recording_key(rec), SENT.lock()) {
        sent.retain(|s| s.recording != key);
    }
}

/// An eye that frames `points` (in the coordinates of the 3D view with origin `origin`):
/// it looks at their centroid from the side the first camera looked from (`view`, its
/// viewing direction, and `up`, its up direction, in the same coordinates), a little from
/// above and to the right, at a distance at which 95 % of the points (by distance from the
/// centroid) about fit the viewer's field of view. `None` without finite points.
pub(super) fn framing_eye(
    points: impl Iterator<Item = [f32; 3]>,
    view: [f64; 3],
    up: [f64; 3],
) -> Option<Eye> {
    use nalgebra::Vector3;
    let pts: Vec<Vector3<f64>> = points
        .map(|p| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    if pts.is_empty() {
        return None;
    }
    let n = pts.len() as f64;
    let centre = pts.iter().fold(Vector3::zeros(), |a, p| a + p) / n;
    let mut dist: Vec<f64> = pts.iter().map(|p| (p - centre).norm()).collect();
    dist.sort_by(f64::total_cmp);
    let r = dist[((dist.len() - 1) as f64 * 0.95).round() as usize].max(1e-9);
    let k = Vector3::from(view);
    let k = if k.norm() > 0.0 {
        k.normalize()
    } else {
        Vector3::z()
    };
    let u = Vector3::from(up);
    // The up direction made orthogonal to the viewing direction.
    let u = u - k * k.dot(&u);
    let u = if u.norm() > 1e-9 {
        u.normalize()
    } else {
        k.cross(&Vector3::x()).normalize()
    };
    let right = k.cross(&u);
    // The viewer's 3D eye has a vertical field of view of about 55°: a sphere of radius r
    // just fits it at a distance of r / sin(27.5°) ≈ 2.2 r; a little farther, for the 5 %
    // of points beyond r and the perspective of the nearer ones (the hotel's facade was cut
    // off at 2.4 r).
    let back = (k - 0.35 * u + 0.25 * right).normalize();
    let eye = centre - back * (2.6 * r);
    let f = |v: Vector3<f64>| [v[0] as f32, v[1] as f32, v[2] as f32];
    Some(Eye {
        position: f(eye),
        target: f(centre),
        up: f(u),
    })
}

/// Records `eye` as the starting eye of the 3D view with origin `origin` of `rec`; the next
/// [`send_layout`] (or [`refresh_layout`]) opens that view on it instead of the viewer's
/// guess, which frames everything, cameras included.
pub(super) fn frame_view(rec: &RecordingStream, origin: &str, eye: Eye) {
    let (Some(key), Ok(mut sent)) = (recording_key(rec), SENT.lock()) else {
        return;
    };
    let k = match sent.iter().position(|s| s.recording == key) {
        Some(k) => k,
        None => {
            sent.push(Sent {
                recording: key,
                parts: None,
                eyes: Vec::new(),
            });
            sent.len() - 1
        }
    };
    let s = &mut sent[k];
    s.eyes.retain(|(o, _)| o != origin);
    s.eyes.push((origin.to_string(), eye));
}

/// [`frame_view`] with the eye of [`framing_eye`] on `points`, seen from the side of the
/// camera whose world-to-camera rotation is `r` (rows: right, down, viewing direction).
pub(super) fn frame_on_camera(
    rec: &RecordingStream,
    origin: &str,
    points: impl Iterator<Item = [f32; 3]>,
    r: &nalgebra::Matrix3<f64>,
) {
    let row = |a: usize| [r[(a, 0)], r[(a, 1)], r[(a, 2)]];
    let [jx, jy, jz] = row(1);
    if let Some(eye) = framing_eye(points, row(2), [-jx, -jy, -jz]) {
        frame_view(rec, origin, eye);
    }
}

/// Sends the layout last sent to `rec` again, with the eyes recorded since
/// ([`frame_view`]); nothing when no layout was sent (a library user's own stream).
pub(super) fn refresh_layout(rec: &RecordingStream) -> RecordingResult {
    let parts = match (recording_key(rec), SENT.lock()) {
        (Some(key), Ok(sent)) => sent
            .iter()
            .find(|s| s.recording == key)
            .and_then(|s| s.parts),
        _ => None,
    };
    match parts {
        Some(parts) => send_layout(rec, parts),
        None => Ok(()),
    }
}

/// The timeline the layout of `parts` opens on: `frame` for a tracking-only recording
/// (`rank3 track`: frames, tracks and tracker counts all live on it), else `stage`.
pub(super) fn layout_timeline(parts: LayoutParts) -> &'static str {
    if parts.tracking && !parts.reconstruction && !parts.objects && !parts.truth {
        TIMELINE_FRAME
    } else {
        TIMELINE_STAGE
    }
}

/// Sends a viewer layout (a Rerun blueprint, made active and the default for the
/// application id) that shows each entity group of the module table in its own view: the
/// image plane (tracks, trajectories, residual arrows, robust flags, frames) beside the 3D
/// scene (metric, affine, truth in tabs); below, W and the mask, the bar charts (singular
/// values, L's eigenvalues, per-point RMS), the time series and the texts (summary, metric
/// upgrade, stage log). Without a layout the viewer guesses one, and its guess for a
/// reconstruction showed no 2D view of the tracks at all.
///
/// * The solvers' progress is five plots side by side, each with its own axis: the cost and
///   the damping λ as log₁₀ (they span many decades) and the RMS in pixels of the
///   least-squares solvers, and RANSAC's best cost (log₁₀) and inlier counts. The viewer
///   0.36 has no logarithmic axis, so the logarithms are logged
///   ([`paths::SOLVER_LOG10_COST`], [`paths::SOLVER_LOG10_LAMBDA`]).
/// * The time panel starts on the timeline where the recording's data live: `frame` for a
///   tracking-only layout (`rank3 track`), else `stage`.
/// * The 3D views open framed on their points: once a structure is logged (metric, affine,
///   perspective, ground truth), the loggers send the layout again with an eye looking at
///   it from the first camera's side.
/// * The blueprint and selection panels start collapsed, leaving the width to the views,
///   and so does the time panel (its controls and the timeline stay in view), leaving them
///   the height.
pub fn send_layout(rec: &RecordingStream, parts: LayoutParts) -> RecordingResult {
    use rerun::blueprint::components::PanelState;
    use rerun::blueprint::{
        BarChartView, Blueprint, BlueprintPanel, ContainerLike, Grid, Horizontal, SelectionPanel,
        Spatial2DView, Spatial3DView, Tabs, TensorView, TextDocumentView, TextLogView, TimePanel,
        TimeSeriesView, Vertical,
    };
    let key = recording_key(rec);
    let known: Vec<(String, Eye)> = match (&key, SENT.lock()) {
        (Some(key), Ok(mut sent)) => match sent.iter_mut().find(|s| &s.recording == key) {
            Some(s) => {
                s.parts = Some(parts);
                s.eyes.clone()
            }
            None => {
                sent.push(Sent {
                    recording: key.clone(),
                    parts: Some(parts),
                    eyes: Vec::new(),
                });
                Vec::new()
            }
        },
        _ => Vec::new(),
    };
    // The eyes of the 3D views, by their blueprint paths.
    let mut eyes: Vec<(String, Eye)> = Vec::new();
    let mut view3d = |name: &str, origin: &str| -> ContainerLike {
        let view: ContainerLike = Spatial3DView::new(name).with_origin(origin).into();
        if let ContainerLike::View(v) = &view
            && let Some((_, eye)) = known.iter().find(|(o, _)| o == origin)
        {
            eyes.push((v.blueprint_path().to_string(), *eye));
        }
        view
    };
    let image = Spatial2DView::new("image: tracks, residuals, robust flags").with_origin("/image");
    let mut scene: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction && parts.perspective {
        scene.push(
            Horizontal::new([
                view3d(
                    "perspective: Euclidean structure, camera frustums",
                    "/perspective/world",
                ),
                view3d("affine model: structure and cameras", "/world"),
            ])
            .into(),
        );
    } else if parts.reconstruction {
        scene.push(view3d("metric structure and cameras", "/world"));
    }
    if parts.reconstruction {
        scene.push(view3d("affine structure", "/affine"));
    }
    if parts.objects {
        scene.insert(
            0,
            view3d(
                "objects: each rigid group's structure and cameras",
                "/objects",
            ),
        );
    }
    if parts.truth {
        scene.push(view3d("ground truth", "/truth"));
    }
    let mut top: Vec<ContainerLike> = vec![image.into()];
    if !scene.is_empty() {
        top.push(Tabs::new(scene).into());
    }
    let mut bottom: Vec<ContainerLike> = Vec::new();
    let mut shares: Vec<f32> = Vec::new();
    if parts.reconstruction {
        bottom.push(
            Tabs::new([
                TensorView::new("W")
                    .with_origin(format!("/{}", paths::W))
                    .into(),
                Spatial2DView::new("visibility mask")
                    .with_origin(format!("/{}", paths::VISIBILITY))
                    .into(),
            ])
            .into(),
        );
        bottom.push(
            Tabs::new(
                [
                    ("singular values", paths::SINGULAR_VALUES),
                    ("eigenvalues of L", paths::EIGENVALUES),
                    ("eigenvalues of least-squares L", paths::EIGENVALUES_LS),
                    ("per-point RMS (px)", paths::POINT_RMS),
                ]
                .map(|(name, path)| {
                    BarChartView::new(name)
                        .with_origin(format!("/{path}"))
                        .into()
                }),
            )
            .into(),
        );
        shares.extend([0.17, 0.17]);
    }
    let mut series: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction {
        // RANSAC's hundreds of hypotheses would squeeze the least-squares solvers' few
        // iterations into the left edge: its series get their own plots.
        let ransac = ["ransac", "ransac-scale"];
        let solver = |name: &str, path: &str| -> ContainerLike {
            TimeSeriesView::new(name)
                .with_origin(format!("/{path}"))
                .with_contents(
                    std::iter::once("+ $origin/**".to_string())
                        .chain(ransac.iter().map(|r| format!("- $origin/{r}/**"))),
                )
                .into()
        };
        let robust = |name: &str, path: &str| -> ContainerLike {
            TimeSeriesView::new(name)
                .with_origin(format!("/{path}"))
                .with_contents(ransac.iter().map(|r| format!("+ $origin/{r}/**")))
                .into()
        };
        series.push(
            Grid::new([
                solver(
                    "solver cost, log₁₀ (iteration timeline)",
                    paths::SOLVER_LOG10_COST,
                ),
                solver("solver damping λ, log₁₀", paths::SOLVER_LOG10_LAMBDA),
                solver("solver RMS (px)", paths::SOLVER_RMS),
                robust("RANSAC best cost, log₁₀", paths::SOLVER_LOG10_COST),
                TimeSeriesView::new("RANSAC inlier tracks")
                    .with_origin(format!("/{}", paths::SOLVER_INLIERS))
                    .into(),
            ])
            .with_grid_columns(3)
            .with_name("solvers (iteration timeline)")
            .into(),
        );
        series.push(
            TimeSeriesView::new("frame RMS (px)")
                .with_origin(format!("/{}", paths::FRAME_RMS))
                .into(),
        );
    }
    if parts.tracking {
        series.push(
            TimeSeriesView::new("tracker counts (frame timeline)")
                .with_origin(format!("/{}", paths::TRACKING))
                .into(),
        );
    }
    if !series.is_empty() {
        bottom.push(Tabs::new(series).into());
        shares.push(if parts.reconstruction { 0.44 } else { 0.6 });
    }
    let mut texts: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction {
        texts.push(
            TextDocumentView::new("summary")
                .with_origin(format!("/{}", paths::SUMMARY))
                .into(),
        );
        texts.push(
            TextDocumentView::new("metric upgrade")
                .with_origin(format!("/{}", paths::METRIC_METHOD))
                .into(),
        );
    }
    texts.push(TextLogView::new("log").with_origin("/log").into());
    bottom.push(Tabs::new(texts).into());
    shares.push(0.22);
    let layout = Vertical::new([
        Horizontal::new(top).into(),
        Horizontal::new(bottom).with_column_shares(shares).into(),
    ])
    .with_row_shares([0.62, 0.38]);
    let blueprint = Blueprint::new(layout)
        .with_time_panel(
            TimePanel::new()
                .with_timeline(layout_timeline(parts))
                .with_state(PanelState::Collapsed),
        )
        .with_blueprint_panel(BlueprintPanel::from_state(PanelState::Collapsed))
        .with_selection_panel(SelectionPanel::from_state(PanelState::Collapsed));
    send_blueprint(rec, &blueprint, &eyes)
}

/// Sends `blueprint` to `rec` with the starting eyes of some of its 3D views (blueprint
/// path, eye), made active and the default for the application id. The Rust SDK 0.36.3 sets
/// no 3D view property (its views have no eye controls; Python's do), so the blueprint's
/// messages are taken from an in-memory stream and each eye is added to them as the
/// `EyeControls3D` property the viewer reads (`<view>/EyeControls3D`, the archetype's
/// documented components), in the same blueprint store, before it is activated.
fn send_blueprint(
    rec: &RecordingStream,
    blueprint: &rerun::blueprint::Blueprint,
    eyes: &[(String, Eye)],
) -> RecordingResult {
    use rerun::blueprint::BlueprintActivation;
    use rerun::log::LogMsg;
    if eyes.is_empty() {
        blueprint.send(rec, BlueprintActivation::default())?;
        return Ok(());
    }
    let application = rec
        .store_info()
        .map(|info| info.application_id().clone())
        .unwrap_or_else(|| "rank3".into());
    let (capture, storage) = rerun::RecordingStreamBuilder::new(application.clone()).memory()?;
    blueprint.send(&capture, BlueprintActivation::default())?;
    let mut messages = Vec::new();
    let mut activation = None;
    for msg in storage.take() {
        match msg {
            LogMsg::BlueprintActivationCommand(cmd) => activation = Some(cmd),
            msg if msg.store_id().is_blueprint() => messages.push(msg),
            _ => {}
        }
    }
    drop(capture);
    let Some(activation) = activation else {
        // Nothing to activate (a disabled stream): send the blueprint as it is.
        blueprint.send(rec, BlueprintActivation::default())?;
        return Ok(());
    };
    let (props, props_storage) = rerun::RecordingStreamBuilder::new(application.clone())
        .recording_id(activation.blueprint_id.recording_id().clone())
        .blueprint()
        .memory()?;
    props.set_time_sequence("blueprint", 0);
    for (view, eye) in eyes {
        props.log_serialized_batches(format!("{view}/EyeControls3D"), false, eye_batches(eye)?)?;
    }
    messages.extend(
        props_storage
            .take()
            .into_iter()
            .filter(|msg| matches!(msg, LogMsg::ArrowMsg(..))),
    );
    drop(props);
    rec.send_blueprint(messages, activation);
    Ok(())
}

/// The components of an `EyeControls3D` blueprint property: an orbital eye at `eye`.
fn eye_batches(eye: &Eye) -> RecordingResult<Vec<rerun::SerializedComponentBatch>> {
    use rerun::ComponentBatch as _;
    use rerun::blueprint::components::Eye3DKind;
    use rerun::components::{Position3D, Vector3D};
    let descriptor =
        |component: &'static str, component_type: &'static str| rerun::ComponentDescriptor {
            archetype: Some("rerun.blueprint.archetypes.EyeControls3D".into()),
            component: component.into(),
            component_type: Some(component_type.into()),
        };
    let batches = [
        [Eye3DKind::Orbital].serialized(descriptor(
            "EyeControls3D:kind",
            "rerun.blueprint.components.Eye3DKind",
        )),
        [Position3D::from(eye.position)].serialized(descriptor(
            "EyeControls3D:position",
            "rerun.components.Position3D",
        )),
        [Position3D::from(eye.target)].serialized(descriptor(
            "EyeControls3D:look_target",
            "rerun.components.Position3D",
        )),
        [Vector3D::from(eye.up)].serialized(descriptor(
            "EyeControls3D:eye_up",
            "rerun.components.Vector3D",
        )),
    ];
    batches
        .into_iter()
        .map(|b| {
            b.ok_or_else(|| {
                super::RecordingError::Input(crate::Error::io(
                    "rerun recording",
                    std::io::Error::other("cannot serialize the 3D view's eye"),
                ))
            })
        })
        .collect()
}
