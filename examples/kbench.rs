use std::time::Instant;
use sublevel::math::Vector3;
use sublevel::Body;
fn main() -> sublevel::Result<()> {
    let d: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let chair = Body::load(&std::path::Path::new("tests/data").join(format!("chair_101.deg{d}.json")))?;
    let f = chair.fast_polynomial();
    let pts: Vec<Vector3> = (0..1024)
        .map(|i| {
            let t = i as f64 * 0.01;
            Vector3::new(t.sin() * 0.3, (1.3 * t).cos() * 0.3, (0.7 * t).sin() * 0.3)
        })
        .collect();
    for round in 0..3 {
        // independent
        let t0 = Instant::now();
        let mut s = 0.0;
        for _ in 0..200 {
            for u in &pts {
                let e = f.eval(std::hint::black_box(u));
                s += e.value + e.hessian[(0, 0)];
            }
        }
        let ind = t0.elapsed().as_secs_f64() * 1e9 / (200.0 * 1024.0);
        // dependent chain: next point depends on the previous eval
        let t0 = Instant::now();
        let mut u = pts[0];
        for _ in 0..200 {
            for p in &pts {
                let e = f.eval(&u);
                u = p + Vector3::new(e.value * 1e-30, e.gradient.x * 1e-30, e.hessian[(2, 2)] * 1e-30);
            }
        }
        let dep = t0.elapsed().as_secs_f64() * 1e9 / (200.0 * 1024.0);
        let t0 = Instant::now();
        let mut s2 = 0.0;
        for _ in 0..200 {
            for u in &pts {
                let (v, g) = f.value_gradient(std::hint::black_box(u));
                s2 += v + g.x;
            }
        }
        let vg = t0.elapsed().as_secs_f64() * 1e9 / (200.0 * 1024.0);
        println!("2d={d} round {round}: full independent {ind:.1} ns, dependent {dep:.1} ns, value+gradient {vg:.1} ns ({s:.3e} {s2:.3e} {})", u.x);
    }
    Ok(())
}
