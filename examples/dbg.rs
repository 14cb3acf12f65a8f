use garment_sim::scene::{Overrides, Scene};
fn main() {
    let which = std::env::args().nth(1).unwrap_or_default();
    let sc = Scene::load(std::path::Path::new("config/scenes/table_drape.yaml")).unwrap();
    let mut sim = sc.build(&Overrides::default()).unwrap();
    let f = &mut sim.fabric;
    if which.contains('b') {
        f.warp.bending = f.warp.bending.without_hysteresis();
        f.weft.bending = f.weft.bending.without_hysteresis();
    }
    if which.contains('t') {
        f.warp.tensile = f.warp.tensile.without_hysteresis();
        f.weft.tensile = f.weft.tensile.without_hysteresis();
    }
    if which.contains('a') {
        let g = f.shear.elastic.c[0];
        for d in [&mut f.warp, &mut f.weft] {
            println!("tensile a {} vs G {}", d.tensile.elastic.c[0], g);
            d.tensile.elastic.c[0] = d.tensile.elastic.c[0].max(1.5 * g);
        }
    }
    if which.contains('s') {
        f.shear = f.shear.without_hysteresis();
    }
    let mut worst: f64 = 0.0;
    let mut last_fast = 0.0;
    for _ in 0..3000 {
        sim.step().unwrap();
        if sim.time > 1.5 {
            worst = worst.max(sim.cloth.v.iter().map(|v| v.norm()).fold(0.0, f64::max));
        }
        if sim.rms_speed() > 0.005 {
            last_fast = sim.time;
        }
    }
    println!("off={which:?} max speed after 1.5 s: {worst:.3} m/s, settle {last_fast:.3}");
}
