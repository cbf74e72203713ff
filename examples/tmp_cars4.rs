// TMP diagnostic, not to be committed.
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rank3::datasets;
use std::io::Write;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let path = &a[1];
    let frac: f64 = a[2].parse().unwrap();
    let seed: u64 = a[3].parse().unwrap();
    let group: usize = a[4].parse().unwrap();
    let out = &a[5];
    let h = datasets::read_hopkins(std::path::Path::new(path)).unwrap();
    let f = h.measurements.n_frames();
    let n0 = h.measurements.n_points();
    let walks = (0.1 * n0 as f64).round() as usize;
    let n = n0 + walks;
    let mut rng = StdRng::seed_from_u64(seed);
    for _ in n0..n {
        let _ = rng.random::<f64>();
        let _ = rng.random::<f64>();
        for _ in 0..f {
            for _ in 0..2 {
                let _ = rng.random::<f64>();
            }
        }
    }
    let mut vis = vec![true; f * n];
    for p in 0..n {
        let k = ((2.0 * frac * rng.random::<f64>()).min(0.9) * f as f64).round() as usize;
        let at_start = rng.random::<bool>();
        for i in 0..k {
            let fr = if at_start { i } else { f - 1 - i };
            vis[fr * n + p] = false;
        }
    }
    let mut o = std::fs::File::create(out).unwrap();
    writeln!(o, "frame,track,x,y").unwrap();
    for p in 0..n0 {
        if h.groups[p] != group {
            continue;
        }
        for fr in 0..f {
            if vis[fr * n + p] {
                writeln!(
                    o,
                    "{fr},{p},{},{}",
                    h.measurements.w[(2 * fr, p)],
                    h.measurements.w[(2 * fr + 1, p)]
                )
                .unwrap();
            }
        }
    }
    eprintln!("image {:?}", h.image_size);
}
