//! The physical bound against real closed-loop runs, and the start of a run on an ARX plant.

use hal_sim::bound::bound;
use hal_sim::scenario::Scenario;
use hal_sim::sim::{run, ControllerChoice, ControllerSpec, PlantChoice, SimOptions};

const ALL: [ControllerChoice; 6] = [
    ControllerChoice::Onoff,
    ControllerChoice::P,
    ControllerChoice::Pi,
    ControllerChoice::Gmvc,
    ControllerChoice::Igmvc,
    ControllerChoice::Gpc,
];

/// No controller beats the bound: every controller's IAE on the three seed cases is at least
/// the bound of the same schedule on the same plant, at two noise seeds and two ambients.
#[test]
fn no_controller_beats_the_bound() {
    for (scenario, plant) in
        [("piecewise", PlantChoice::Hter1), ("half-load", PlantChoice::Hter1), ("piecewise", PlantChoice::Hter2)]
    {
        for (ambient_c, seed) in [(28.0, 1), (36.0, 5)] {
            let base = SimOptions {
                plant,
                ambient_c,
                seed,
                ..SimOptions::new(Scenario::resolve(scenario).unwrap(), ControllerSpec::new(ControllerChoice::Gpc))
            };
            let b = bound(&base).unwrap();
            assert!(b.iae > 0.0 && b.changes_ignored == 0, "{b:?}");
            for c in ALL {
                let m = run(&SimOptions { controller: ControllerSpec::new(c), ..base.clone() }).unwrap().metrics;
                assert!(
                    m.tracking.iae >= b.iae,
                    "{c:?} on {scenario} {plant:?} at {ambient_c} °C seed {seed}: IAE {} below the bound {}",
                    m.tracking.iae,
                    b.iae
                );
            }
        }
    }
}

/// The bound of a pull-down from ambient: full cooling from 28 °C, which takes the carrier to
/// 4 °C in ≈ 30 min (`plant.rs`): IAE between the triangle ½·24 °C·1500 s and the rectangle
/// 24 °C·3600 s, and below every controller's.
#[test]
fn the_pull_down_bound_is_the_full_cooling_run() {
    let opts = SimOptions::new(Scenario::resolve("step").unwrap(), ControllerSpec::new(ControllerChoice::Pi));
    let b = bound(&opts).unwrap();
    let crossed = b.segments[0].crossed_s.unwrap();
    assert!((1500.0..=3600.0).contains(&crossed), "{b:?}");
    assert!(b.iae > 0.5 * 24.0 * 1500.0 && b.iae < 24.0 * crossed, "{b:?}");
    let pi = run(&opts).unwrap().metrics.tracking.iae;
    assert!(pi >= b.iae, "PI {pi} vs bound {}", b.iae);
    // And the disturbance scenario, whose only event is a heat step, has no setpoint
    // transient: its bound is 0 and says what it left out.
    let d = SimOptions::new(Scenario::resolve("disturbance").unwrap(), ControllerSpec::new(ControllerChoice::Pi));
    let b = bound(&d).unwrap();
    assert_eq!((b.iae, b.changes_ignored), (0.0, 1));
}

/// On an ideal ARX plant started at steady state, the loop starts at the plant's steady duty:
/// the first duty of a run at zero error is that duty (u_ss = y_ss·A(1)/B(1)), not 0.
#[test]
fn an_arx_run_starts_at_the_plants_steady_duty() {
    let spec = "arx:-1.88715,0.88824;-0.0073535,-0.019729;1";
    let m = hal_sim::arx::parse(spec).unwrap();
    // Holding 4 °C at 14 °C ambient: y = −10, A(1) = 0.00109, B(1) = −0.0271025.
    let u_ss = -10.0 * (1.0 - 1.88715 + 0.88824) / (-0.0073535 - 0.019729);
    assert!((0.3..0.5).contains(&u_ss), "{u_ss}");
    let mut fixed = ControllerSpec::new(ControllerChoice::Gpc);
    fixed.model = Some(m);
    for controller in [ControllerSpec::new(ControllerChoice::Pi), fixed, ControllerSpec::new(ControllerChoice::Gpc)] {
        let opts = SimOptions {
            plant: PlantChoice::Arx(m),
            ambient_c: 14.0,
            ..SimOptions::new(Scenario::resolve("piecewise").unwrap(), controller)
        };
        let out = run(&opts).unwrap();
        let first = &out.rows[0];
        assert!((first.true_temp_c - 4.0).abs() < 1e-9, "{:?}", first.true_temp_c);
        // f32 model coefficients and the f32 duty: 1e-3.
        assert!(
            (first.duty - u_ss).abs() < 1e-3,
            "{:?}: first duty {} vs steady {u_ss}",
            controller.choice,
            first.duty
        );
        // And it holds there until the first setpoint change at 200 s.
        assert!(out.rows[..20].iter().all(|r| (r.true_temp_c - 4.0).abs() < 1e-3), "{:?}", controller.choice);
    }
}

/// A scenario file's `start_c` is where the run and the bound start, on the physical carrier
/// too. The pre-roll held the schedule's first setpoint, so `start_c` 20 with a 4 °C setpoint
/// started at 4.0 °C (any `start_c` 0–28 gave the same run) while the bound started at 20 °C,
/// and On-Off and PI "beat" the physical bound (IAE ratios 0.04 and 0.00). The run now starts
/// where the bound does, the plant's steady state holding `start_c` (20 °C, and 6 °C inside the
/// board's setpoint range): the first sample and the bound's start agree with `start_c`, and no
/// controller beats the bound.
#[test]
fn a_scenario_files_start_c_is_where_the_run_and_the_bound_start() {
    use hal_sim::scenario::Start;
    for start_c in [20.0, 6.0] {
        let sc = Scenario {
            start: Start::Holding(start_c),
            setpoints: vec![(0.0, 4.0)],
            changes: vec![],
            duration_s: 300.0,
            ..Scenario::resolve("piecewise").unwrap()
        };
        let base = SimOptions::new(sc, ControllerSpec::new(ControllerChoice::Gpc));
        let b = bound(&base).unwrap();
        assert_eq!(b.segments[0].from_c, start_c, "{b:?}");
        assert!(b.iae > 0.0, "{b:?}");
        for c in [ControllerChoice::Onoff, ControllerChoice::Pi, ControllerChoice::Gpc] {
            let out = run(&SimOptions { controller: ControllerSpec::new(c), ..base.clone() }).unwrap();
            // The steady state is found to the search's tolerance.
            let first = out.rows[0].true_temp_c;
            assert!((first - start_c).abs() < 0.01, "{c:?} from {start_c} °C: first sample at {first} °C");
            assert!(
                out.metrics.tracking.iae >= b.iae,
                "{c:?} from {start_c} °C: IAE {} below the bound {}",
                out.metrics.tracking.iae,
                b.iae
            );
        }
    }
    // Above the ambient no duty holds it: refused by the run and the bound alike.
    let sc = Scenario { start: Start::Holding(30.0), ..Scenario::resolve("piecewise").unwrap() };
    let base = SimOptions::new(sc, ControllerSpec::new(ControllerChoice::Pi));
    assert!(run(&base).is_err() && bound(&base).is_err());
}
