//! Frames per second of the renderer on a scene, one thread, and the last frame as a PPM:
//! `cargo run --release -p diffcloth-render --example render_fps -- diffcloth_gym/configs/hat.toml 480 480 out.ppm [steps]`

use diffcloth_render::{Renderer, SceneView};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map_or("diffcloth_gym/configs/hat.toml", String::as_str);
    let width: usize = args.get(2).map_or(Ok(480), |s| s.parse())?;
    let height: usize = args.get(3).map_or(Ok(480), |s| s.parse())?;
    let steps: usize = args.get(5).map_or(Ok(0), |s| s.parse())?;
    diffcloth::init_linear_algebra();
    let mut sim = diffcloth::Simulator::from_toml_file(std::path::Path::new(path))?;
    for _ in 0..steps {
        sim.step(Default::default())?;
    }
    let mut renderer = Renderer::new(width, height)?;
    let mut frame = vec![0u8; width * height * 3];
    let scene = SceneView::of(&sim);
    renderer.render(&scene, None, &mut frame)?;
    let frames: usize = args.get(6).map_or(Ok(300), |s| s.parse())?;
    let start = Instant::now();
    for _ in 0..frames {
        renderer.render(&scene, None, &mut frame)?;
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{path} {width}x{height}: {:.0} frames/s ({:.3} ms/frame)",
        frames as f64 / secs,
        1e3 * secs / frames as f64
    );
    if let Some(out) = args.get(4) {
        let mut ppm = format!("P6\n{width} {height}\n255\n").into_bytes();
        ppm.extend_from_slice(&frame);
        std::fs::write(out, ppm)?;
    }
    Ok(())
}
