//! Timing of the Canny edge detector (moved out of the unit tests: timing is not a test):
//! the median wall time of `Canny::detect` (thresholds 40/120, the AVX2 build where the CPU
//! has it) over 200 runs on blocky texture plus noise, at 320x240 and 640x480. The figures in
//! the `canny` module notes come from this.
//!
//! Run: `cargo run --release -p hvs-fusion --example canny_timing`.

use hvs_fusion::Canny;

/// Small deterministic PRNG (xorshift64*), the one the unit tests use.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn byte(&mut self) -> u8 {
        (self.next() >> 56) as u8
    }
}

/// Blocky texture (random grey per 8x8 block) plus a little noise: many edges in all
/// directions, like a real scene.
fn textured_image(rng: &mut Rng, w: usize, h: usize) -> Vec<u8> {
    let (bw, bh) = (w.div_ceil(8), h.div_ceil(8));
    let blocks: Vec<u8> = (0..bw * bh).map(|_| rng.byte()).collect();
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let noise = (rng.byte() % 16) as i32 - 8;
            (blocks[(y / 8) * bw + x / 8] as i32 + noise).clamp(0, 255) as u8
        })
        .collect()
}

/// Median time of `detect` over `runs` calls on a textured `w x h` image, in us.
fn median_detect_us(w: usize, h: usize, runs: usize) -> f64 {
    let mut rng = Rng(12345);
    let img = textured_image(&mut rng, w, h);
    let mut edges = vec![0u8; w * h];
    let mut canny = Canny::new();
    canny.detect(&img, w, h, 40, 120, &mut edges);
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let t = std::time::Instant::now();
            let n = canny.detect(std::hint::black_box(&img), w, h, 40, 120, &mut edges);
            std::hint::black_box(n);
            t.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[runs / 2]
}

fn main() {
    let runs = 200;
    for &(w, h) in &[(320, 240), (640, 480)] {
        let us = median_detect_us(w, h, runs);
        println!("canny {w}x{h} detect: median {us:.1} us over {runs} runs");
    }
}
