//! Processor-in-the-loop runner: the library's per-sample step ([`hter::step::Carrier`]) on a
//! Cortex-M4F, emulated by QEMU (`-M mps2-an386`), fed recorded ADC counts and timed with
//! SysTick under `-icount shift=6` (one instruction = 64 ns of virtual time = 1.6 SysTick
//! counts at 25 MHz; the runner measures that ratio itself with a loop of known length).
//!
//! `cargo xtask pil` writes the counts to `pil-in.bin`, starts QEMU in that directory, and
//! compares what this runner writes to `pil-out.bin` with the same samples run on the host
//! ([`proto`] holds what both sides share). Host files are read and written through ARM
//! semihosting; the exit status says whether the run completed. It builds this runner twice:
//! with `pil/Cargo.toml`'s release profile (this crate at opt-level 3, the budgeted figures) and
//! with its `board` profile (this crate at "z", as the firmware crate: the firmware's step).
//!
//! Per sample the runner times the real work — `Carrier::step` and the cold-chain monitor's
//! `push` — and then, on shadow copies that do not touch the real state, the parts of it:
//! the controller update alone, the counts → °C conversion, a 5- and a 4-parameter RLS update
//! on the self-tuning controller's regressor (the library's `SecondOrderRegressor`, fed as the
//! self-tuner feeds its own), the GPC design, the estimate's projection and a Diophantine
//! solution.
#![no_std]
#![no_main]

mod proto;

use core::arch::asm;
use core::hint::black_box;
use core::sync::atomic::{compiler_fence, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln, nr, syscall};
use hter::alarm::Annunciator;
use hter::control::adaptive::{plausible_model, SecondOrderRegressor};
use hter::control::gpc::{GpcConfig, GpcStaged, GpcState};
use hter::control::{AnyController, ControlInput, Controller};
use hter::ident::rls::Rls;
use hter::persist::{HistoryRecord, Recorder};
// The board's boot duty, where the self-tuning controller starts.
use hter::profile::BOOT_DUTY;
use hter::step::{BoardReadings, Carrier, StepInput, StepOutput};
use nalgebra::SVector;

/// Samples read from the host per semihosting call.
const CHUNK: usize = 64;
/// Stack words painted at start, to measure the peak stack depth.
const PAINT_WORDS: usize = 16 * 1024;
const PAINT: u32 = 0xdead_beef;

#[entry]
fn main() -> ! {
    let code = match run() {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(msg) => {
            hprintln!("pil: {}", msg);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(code);
    #[allow(clippy::empty_loop)]
    loop {}
}

/// SysTick now (counts down). The fences keep the timed code between two reads.
#[inline(always)]
fn now() -> u32 {
    compiler_fence(Ordering::SeqCst);
    let v = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    v
}

/// Counts elapsed between two [`now`] readings (24-bit down-counter, at most one wrap).
#[inline(always)]
fn since(t0: u32, t1: u32) -> u32 {
    t0.wrapping_sub(t1) & 0x00ff_ffff
}

/// Exactly 2n + 0 instructions of loop body (`subs`, `bne`) plus the call.
#[inline(never)]
fn spin(n: u32) {
    // SAFETY: register-only loop, no memory or stack access.
    unsafe {
        asm!("2:", "subs {0}, {0}, #1", "bne 2b", inout(reg) n => _, options(nomem, nostack));
    }
}

/// Times `f` in SysTick counts.
#[inline(always)]
fn timed<R>(f: impl FnOnce() -> R) -> (R, u32) {
    let t0 = now();
    let r = black_box(f());
    let t1 = now();
    (r, since(t0, t1))
}

/// A host file opened through semihosting.
struct HostFile(usize);

impl HostFile {
    fn open(name: &str, mode: usize) -> Result<Self, &'static str> {
        // SAFETY: `name` is NUL-terminated (proto's constants); length excludes the NUL.
        let fd = unsafe { syscall!(OPEN, name.as_ptr(), mode, name.len() - 1) } as isize;
        if fd < 0 {
            return Err("cannot open a host file");
        }
        Ok(Self(fd as usize))
    }

    /// Fills `buf` completely or fails.
    fn read_exact(&mut self, buf: &mut [u8]) -> Result<(), &'static str> {
        // SAFETY: the buffer is valid for writes of its length. SYS_READ returns bytes NOT read.
        let left = unsafe { syscall!(READ, self.0, buf.as_mut_ptr(), buf.len()) };
        if left == 0 {
            Ok(())
        } else {
            Err("input file too short")
        }
    }

    fn write_all(&mut self, buf: &[u8]) -> Result<(), &'static str> {
        // SAFETY: the buffer is valid for reads of its length. SYS_WRITE returns bytes NOT written.
        let left = unsafe { syscall!(WRITE, self.0, buf.as_ptr(), buf.len()) };
        if left == 0 {
            Ok(())
        } else {
            Err("short write to the output file")
        }
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        // SAFETY: closes the descriptor this value owns.
        unsafe { syscall!(CLOSE, self.0) };
    }
}

/// Buffered little-endian u32 writer to a host file.
struct Out {
    file: HostFile,
    buf: [u8; 4096],
    len: usize,
}

impl Out {
    fn word(&mut self, w: u32) -> Result<(), &'static str> {
        if self.len + 4 > self.buf.len() {
            self.flush()?;
        }
        self.buf[self.len..self.len + 4].copy_from_slice(&w.to_le_bytes());
        self.len += 4;
        Ok(())
    }

    fn flush(&mut self) -> Result<(), &'static str> {
        let r = self.file.write_all(&self.buf[..self.len]);
        self.len = 0;
        r
    }
}

fn word(b: &[u8], i: usize) -> u32 {
    let mut w = [0u8; 4];
    w.copy_from_slice(&b[4 * i..4 * i + 4]);
    u32::from_le_bytes(w)
}

/// Paints the stack below the current frame (with a margin) so [`stack_peak`] can find the
/// deepest word written.
fn paint_stack() {
    let sp = cortex_m::register::msp::read() as usize;
    let lo = stack_top() - 4 * PAINT_WORDS;
    let mut p = lo;
    while p + 256 < sp {
        // SAFETY: [lo, sp − 256) is unused stack inside RAM (4 MiB, far below any data).
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

fn stack_top() -> usize {
    extern "C" {
        static _stack_start: u32;
    }
    // Only the symbol's address is taken.
    core::ptr::addr_of!(_stack_start) as usize
}

/// Deepest stack use since [`paint_stack`], bytes.
fn stack_peak() -> u32 {
    let lo = stack_top() - 4 * PAINT_WORDS;
    let mut p = lo;
    // SAFETY: reads of the painted region.
    while p < stack_top() && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    (stack_top() - p) as u32
}

fn run() -> Result<(), &'static str> {
    // The firmware's stack guard (its memory.x and `failsafe::arm_stack_guard`): the step runs
    // with it on, as on the board.
    let g = hter::failsafe::stack_guard();
    // SAFETY: the guard is pil/memory.x's `.stack_guard`, which holds nothing.
    if !unsafe { hter::failsafe::arm_stack_guard(g.start, g.end) } {
        return Err("the stack guard is not one MPU region");
    }
    let mut cp = cortex_m::Peripherals::take().ok_or("peripherals taken")?;
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00ff_ffff);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();
    paint_stack();

    // Calibration: an empty window, and loops of exactly 2000 and 4000 instructions.
    let (_, empty) = timed(|| ());
    let (_, short) = timed(|| spin(black_box(proto::CAL_LOOP)));
    let (_, long) = timed(|| spin(black_box(2 * proto::CAL_LOOP)));

    let mut input = HostFile::open(proto::INPUT_FILE, nr::open::R_BINARY)?;
    let mut head = [0u8; 12];
    input.read_exact(&mut head)?;
    if word(&head, 0) != proto::MAGIC_IN {
        return Err("input file has no PIL header");
    }
    let kind = word(&head, 1);
    let n = word(&head, 2) as usize;
    let (mut carrier, mut monitor) = proto::carrier(kind).ok_or("unknown controller kind")?;

    let out_file = HostFile::open(proto::OUTPUT_FILE, nr::open::W_TRUNC_BINARY)?;
    let mut out = Out { file: out_file, buf: [0; 4096], len: 0 };
    for w in [proto::MAGIC_OUT, empty, short, long, n as u32] {
        out.word(w)?;
    }

    // Shadows for the profile.
    let acfg = proto::ADAPTIVE;
    let m0 = acfg.initial.unwrap_or(hter::model::Model::NEUTRAL);
    let (a0, b0) = (m0.a(), m0.b());
    let theta7 = SVector::<f32, 7>::from([a0[0], a0[1], b0[0], b0[1], b0[2], b0[3], 0.0]);
    let theta5 = SVector::<f32, 5>::from([a0[0], a0[1], b0[0], b0[1], 0.0]);
    let mut rls7 = Rls::new(&acfg.rls, theta7);
    let mut rls5 = Rls::new(&acfg.rls, theta5);
    // The self-tuner's own regressor type, fed beside it as the self-tuner feeds its own.
    let mut reg = SecondOrderRegressor::new(acfg.k, BOOT_DUTY).map_err(|_| "the profile's delay is refused")?;
    let mut gpc = GpcState::new(BOOT_DUTY);
    // Kept between samples, as `LawState` does.
    let mut gpc_design = GpcStaged::NEW;
    // The firmware's record and indicator, timed beside the step as the control task runs them.
    let mut recorder = Recorder::new(HistoryRecord::EMPTY, proto::HISTORY_SAVE_SAMPLES);
    let mut annunciator = Annunciator::new();

    const SAMPLE_BYTES: usize = 4 * proto::INPUT_WORDS;
    let mut chunk = [0u8; SAMPLE_BYTES * CHUNK];
    let mut done = 0;
    while done < n {
        let take = (n - done).min(CHUNK);
        input.read_exact(&mut chunk[..SAMPLE_BYTES * take])?;
        for s in 0..take {
            let (inp, board): (StepInput, BoardReadings) =
                proto::input_of(core::array::from_fn(|i| word(&chunk, proto::INPUT_WORDS * s + i)));
            let mut ticks = [0u32; proto::PARTS.len()];
            let ctrl_before: AnyController = carrier.controller().clone();

            // The measured per-sample work.
            let inp_b = black_box(inp);
            let board_b = black_box(board);
            // The readings handed over and the step: the control task's per-sample work.
            let t0 = now();
            carrier.observe(&board_b);
            let o = step(&mut carrier, &inp_b);
            let t = since(t0, now());
            ticks[proto::PART_STEP] = t;
            let (raised, t) = timed(|| proto::monitor_push(&mut monitor, &inp_b, &o));
            ticks[proto::PART_MONITOR] = t;
            ticks[proto::PART_BOARD] = timed(|| {
                let mut rec = recorder.push(inp_b.t_ms, o.recorded_c());
                let alarm = annunciator.update(&o, &rec.raised);
                recorder.note_carried(&mut rec, annunciator.latched(), carrier.sensor_offset(), carrier.ssr_shorted());
                if rec.save_due {
                    // What the control task hands the persist task (its queue copies it once).
                    black_box(recorder.history());
                }
                alarm
            })
            .1;

            // Profile on shadows.
            let ci = ControlInput { y_c: o.temp_c.0, w_c: o.setpoint_c.0 };
            let mut c2 = ctrl_before;
            ticks[2] = timed(|| c2.update(&ci)).1;
            let cfg = proto::CARRIER.get();
            ticks[3] = timed(|| cfg.adc.ohms(inp.counts).ok().and_then(|r| cfg.rtd.temperature(r).ok())).1;
            let st = match carrier.controller() {
                AnyController::SelfTuning(st) => Some(st),
                _ => None,
            };
            if reg.push_y(o.temp_c.0) {
                let phi7 = reg.phi();
                let phi5 = SVector::<f32, 5>::from([phi7[0], phi7[1], phi7[2], phi7[3], 1.0]);
                ticks[4] = timed(|| rls7.update(&acfg.rls, &phi7, reg.y()).is_ok()).1;
                ticks[5] = timed(|| rls5.update(&acfg.rls, &phi5, reg.y()).is_ok()).1;
            }
            let model = st.and_then(|s| s.trusted_model()).unwrap_or(m0);
            let gcfg = GpcConfig::DEFAULT;
            ticks[6] = timed(|| {
                gpc.push_y(o.temp_c.0, &model).is_ok() && gpc_design.update(&gpc, &model, &gcfg, o.setpoint_c.0).is_ok()
            })
            .1;
            gpc.track(o.duty.get());
            if let Some(st) = st {
                ticks[7] = timed(|| st.estimate().is_some_and(|m| plausible_model(&acfg, &m))).1;
            }
            let at = model.atilde();
            ticks[8] =
                timed(|| hter::control::diophantine::solve(&at[..model.na() + 2], &[1.0], model.k()).map(|s| s.f[0])).1;
            reg.push_u(o.duty.get());

            out.word(o.duty.get().to_bits())?;
            for t in ticks {
                out.word(t)?;
            }
            let mut ev = [(0u32, 0u32); proto::MAX_EVENT_WORDS];
            let mut m = 0;
            proto::event_words(&o, &raised, |c, v| {
                if let Some(slot) = ev.get_mut(m) {
                    *slot = (c, v);
                    m += 1;
                }
            });
            out.word(m as u32)?;
            for (c, v) in &ev[..m] {
                out.word(*c)?;
                out.word(*v)?;
            }
        }
        done += take;
    }
    out.word(stack_peak())?;
    // RAM of the control state itself (the runner keeps it on the stack).
    let state = core::mem::size_of::<hter::step::Carrier<AnyController>>()
        + core::mem::size_of::<hter::coldchain::ColdChainMonitor>();
    out.word(state as u32)?;
    out.flush()
}

/// The measured step, as a call: the firmware calls `Carrier::step` out of line too, and the
/// count then holds the step and the call, whether or not the compiler would have inlined the
/// step into this loop (which changes with the size of everything around it, and puts a copy
/// of the output inside the window when it does not).
#[inline(never)]
fn step(carrier: &mut Carrier<AnyController>, input: &StepInput) -> StepOutput {
    carrier.step(input)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("pil: panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}
