use hal_sim::plant::{Load, Plant, PlantParams};
fn main() {
    for (name, f) in [("hter1", PlantParams::hter1 as fn(Load) -> PlantParams), ("hter2", PlantParams::hter2)] {
        for load in [Load::Full, Load::Half] {
            for amb in [25.0, 32.0, 43.0] {
                let Some((mut p, d)) = Plant::at_load_temperature(f(load), amb, 4.0) else {
                    println!("{name} {load:?} {amb}: cannot hold");
                    continue;
                };
                let nodes = p.node_temps_c();
                p.set_supply_v(0.0);
                let mut t = 0.0;
                let mut t5 = None;
                let mut t6 = None;
                while p.load_temp_c() <= 8.0 && t < 48.0 * 3600.0 {
                    p.advance_pwm_period(1.0, 1.0);
                    t += 1.0;
                    if t5.is_none() && p.load_temp_c() > 5.0 {
                        t5 = Some(t);
                    }
                    if t6.is_none() && p.load_temp_c() > 6.0 {
                        t6 = Some(t);
                    }
                }
                let tau = t / ((amb - 4.0) / (amb - 8.0f64)).ln();
                println!("{name} {load:?} {amb}: duty {d:.3} (amb-T)/d {:.1} t_act {t} s t5 {t5:?} t6 {t6:?} tau_eff {tau:.0} nodes {nodes:.1?}", (amb - 4.0) / d);
            }
        }
    }
}
