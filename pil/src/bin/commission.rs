//! Instructions per sample of on-board commissioning ([`hter::ident::commission`]) on the
//! emulated Cortex-M4F: the record phases and every pass of the fit, on an ideal second-order
//! plant (H-TER I's output-error poles, k = 9). Run by hand:
//! `cargo build --release --bin commission` in `pil/`, then
//! `qemu-system-arm -M mps2-an386 -display none -monitor none -serial none -semihosting-config
//! enable=on,target=native -icount shift=6,sleep=off -kernel target/thumbv7em-none-eabihf/release/commission`.
//! SysTick counts ÷ 1.6 = instructions (`-icount shift=6` at 25 MHz).
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::{compiler_fence, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use hter::control::{ControlInput, Controller};
use hter::ident::commission::{CommissionConfig, Commissioning, Phase};

#[inline(always)]
fn now() -> u32 {
    compiler_fence(Ordering::SeqCst);
    let v = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    v
}

#[entry]
fn main() -> ! {
    let mut cp = cortex_m::Peripherals::take().unwrap();
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00ff_ffff);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();
    // y(t) = 1.9400 y(t−1) − 0.9401 y(t−2) − 0.0279 u(t−9) − 0.0271 u(t−10): cooling, two lags.
    let (a1, a2, b0, b1, k) = (-1.939_966f32, 0.940_146f32, -0.027_9f32, -0.027_1f32, 9usize);
    let u0 = 0.45f32;
    let mut c = Commissioning::new(CommissionConfig::DEFAULT, 10.0, u0).unwrap();
    let (mut y, mut u) = ([0.0f32; 2], [0.0f32; 16]);
    let (mut rec_max, mut fit_max, mut fit_sum, mut fits) = (0u32, 0u32, 0u64, 0u32);
    for t in 0..4000usize {
        let input = ControlInput { y_c: 4.0 + y[0], w_c: 4.0 };
        let fitting = matches!(c.phase(), Phase::Fit { .. });
        let t0 = now();
        let d = black_box(c.update(&input)).unwrap_or(u0);
        c.track(&input, d);
        let t1 = now();
        let n = t0.wrapping_sub(t1) & 0x00ff_ffff;
        if fitting {
            fit_max = fit_max.max(n);
            fit_sum += u64::from(n);
            fits += 1;
        } else {
            rec_max = rec_max.max(n);
        }
        if c.outcome().is_some() {
            break;
        }
        u[t & 15] = d - u0;
        let uk = u[(t + 1).wrapping_sub(k) & 15];
        let uk1 = u[(t + 1).wrapping_sub(k + 1) & 15];
        y = [-a1 * y[0] - a2 * y[1] + b0 * uk + b1 * uk1, y[0]];
    }
    let ins = |counts: u64| counts * 10 / 16;
    hprintln!(
        "commission: size_of {} bytes; rest/excite max {} instructions/sample; fit {} passes, max {} mean {} instructions/pass; outcome ok {}; fit {:?}",
        core::mem::size_of::<Commissioning>(),
        ins(u64::from(rec_max)),
        fits,
        ins(u64::from(fit_max)),
        ins(fit_sum / u64::from(fits.max(1))),
        matches!(c.outcome(), Some(Ok(_))),
        c.fit_percent()
    );
    debug::exit(debug::EXIT_SUCCESS);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("commission: panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}
