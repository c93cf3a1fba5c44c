//! Renders a map at its start pose (or a given pose) into a directory and prints the render time.
//!
//! `cargo run --release -p hvs-sim --example render_demo -- MAP OUT_DIR [x,y,heading_deg] [qvga]`

use std::path::PathBuf;
use std::time::Instant;

use hvs_sim::{GridMap, Pose, RenderSize, Renderer, WebcamDefects, render_to_dir};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: render_demo MAP OUT_DIR [x,y,heading_deg] [qvga]".into());
    }
    let map_path = PathBuf::from(&args[1]);
    let out = PathBuf::from(&args[2]);
    let map = GridMap::load(&map_path)?;
    let pose: Pose = match args.get(3) {
        Some(p) => p.parse()?,
        None => map.start_pose(),
    };
    let size = if args.get(4).is_some_and(|s| s == "qvga") {
        RenderSize::Qvga
    } else {
        RenderSize::Vga
    };
    let files = render_to_dir(&map_path, &pose, &out, size, &WebcamDefects::none())?;
    let renderer = Renderer::new(&map, size.rig());
    let n = size.rig().pixels();
    let (mut l, mut r, mut g) = (vec![0u8; n], vec![0u8; n], vec![0u16; n]);
    let reps = 60;
    let mut times_ms = Vec::with_capacity(reps);
    for _ in 0..reps {
        let t0 = Instant::now();
        renderer.render_pair(&pose, &pose, &mut l, &mut r, Some(&mut g))?;
        times_ms.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    times_ms.sort_by(f64::total_cmp);
    println!(
        "wrote {:?}; render_pair+gt min {:.2} ms, median {:.2} ms",
        files.left_png,
        times_ms[0],
        times_ms[reps / 2]
    );
    Ok(())
}
