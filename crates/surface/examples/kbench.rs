use fewview_surface::cputime::measure;
use fewview_surface::hashgrid::{HashGridConfig, init_table, kernels};
use fewview_surface::mlp::{Activation, MlpSpec, init_default, kernels as mk};
fn main() {
    let lay = HashGridConfig::default().layout().unwrap();
    let table = init_table(&lay, 1);
    let n = 164_000;
    let pts: Vec<f32> = (0..n * 3)
        .map(|i| (((i * 7919) % 10007) as f32 / 10007.0) * 1.2 - 0.6)
        .collect();
    let win = vec![1.0f32; 16];
    let (out, w, c) = measure(|| kernels::forward(&lay, &table, &win, &pts));
    println!("hash fwd {n}: wall {w:.3} cpu {c:.3}");
    let (_, w, c) = measure(|| kernels::backward_table(&lay, &win, &pts, &out));
    println!("hash bwd table: wall {w:.3} cpu {c:.3}");
    let (_, w, c) = measure(|| kernels::backward_positions(&lay, &table, &win, &pts, &out));
    println!("hash bwd pos: wall {w:.3} cpu {c:.3}");
    let spec = MlpSpec {
        dims: vec![35, 64, 16],
        hidden: Activation::Relu,
        output: Activation::None,
    };
    let p = init_default(&spec, 1);
    let x: Vec<f32> = (0..n * 35).map(|i| ((i % 97) as f32) / 97.0).collect();
    let (y, w, c) = measure(|| mk::forward(&spec, &p, &x));
    println!("mlp fwd: wall {w:.3} cpu {c:.3}");
    let (_, w, c) = measure(|| mk::backward(&spec, &p, &x, &y, true));
    println!("mlp bwd: wall {w:.3} cpu {c:.3}");
}
