use rank3::perspective::PerspectiveConfig;
use rank3::synth::{Shape, SynthConfig, generate};
use rank3::{CameraModel, Config, Reconstruction};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let missing: f64 = args.get(1).map_or(0.0, |s| s.parse().unwrap());
    let noise: f64 = args.get(2).map_or(0.0, |s| s.parse().unwrap());
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 14,
        points: 60,
        noise,
        missing,
        distance: 2.5,
        seed: 1,
        ..SynthConfig::default()
    })
    .unwrap();
    let cfg = Config {
        camera: CameraModel::Perspective,
        robust: None,
        perspective: PerspectiveConfig::default(),
        ..Config::default()
    };
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let t = s.perspective.as_ref().unwrap();
    println!("true f {}", t.intrinsics[0][(0, 0)]);
    let p = rec.projective.as_ref().unwrap();
    println!("projective rms {}", p.rms_px);
    let per = rec.perspective.as_ref().unwrap();
    println!("selfcal {:?}", per.self_calibration);
    for st in &per.stages {
        println!("{st:?}");
    }
    println!(
        "intr {:?} rms {} front {}",
        per.intrinsics, per.rms_px, per.in_front
    );
}
