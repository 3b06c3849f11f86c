//! Pseudo-random binary sequence from a maximum-length linear feedback shift register
//! (Ljung, *System Identification*, 2nd ed., 1999, §13.3 "Input signals", PRBS; taps from
//! Xilinx XAPP052, "Efficient shift registers, LFSR counters and long pseudo-random sequence
//! generators", 1996). Runs on the MCU: no allocation, one shift and a popcount per bit.
//!
//! ```text
//! s(k+1) = (s(k) << 1 | parity(s(k) & taps)) mod 2ⁿ        Fibonacci LFSR, n = `bits`
//! x(k)   = newest bit of s(k)
//! u(t)   = high if x(⌊t / hold⌋) = 1, else low
//! ```
//!
//! An n-bit register with maximum-length taps visits all 2ⁿ − 1 non-zero states, so the bit
//! sequence has period 2ⁿ − 1 with 2ⁿ⁻¹ ones and 2ⁿ⁻¹ − 1 zeros (ones − zeros = 1 per period)
//! and an almost white spectrum up to 1/(2·hold·Ts). Each bit is held for `hold` samples: a
//! slow plant needs `hold · Ts` of the order of its dominant time constant / 3 or longer, else
//! the excitation is all above its bandwidth. The levels `low`/`high` are duties in [0, 1]
//! when the sequence drives the SSR. [`Prbs::with_length`] stops the sequence after a given
//! number of samples (an identification experiment of fixed length).
//!
//! Glossary: LFSR — linear feedback shift register; taps — the register bits XORed into the
//! feedback; hold — samples per bit; period — 2ⁿ − 1 bits = (2ⁿ − 1)·hold samples.

/// Why a PRBS configuration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PrbsError {
    /// Register length outside 3…16 bits.
    Bits,
    /// hold is zero, or the levels are not finite with low < high.
    Levels,
}

/// Feedback taps (1-based bit positions) of maximum-length registers, XAPP052 table 3.
const TAPS: [(u8, u16); 14] = [
    (3, 0b110),
    (4, 0b1100),
    (5, 0b1_0100),
    (6, 0b11_0000),
    (7, 0b110_0000),
    (8, 0b1011_1000),
    (9, 0b1_0001_0000),
    (10, 0b10_0100_0000),
    (11, 0b101_0000_0000),
    (12, 0b1000_0010_1001),
    (13, 0b1_0000_0000_1101),
    (14, 0b10_0000_0001_0101),
    (15, 0b110_0000_0000_0000),
    (16, 0b1101_0000_0000_1000),
];

/// PRBS settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PrbsConfig {
    /// Register length, bits (3…16): period 2ⁿ − 1 bits.
    pub bits: u8,
    /// Samples each bit is held (≥ 1): sets the lowest excited frequency's resolution.
    pub hold: u16,
    /// Output for a 0 bit (a duty in [0, 1] when it drives the SSR).
    pub low: f32,
    /// Output for a 1 bit.
    pub high: f32,
}

/// The generator.
#[derive(Clone, Debug)]
pub struct Prbs {
    cfg: PrbsConfig,
    mask: u16,
    taps: u16,
    state: u16,
    held: u16,
    bit: bool,
    /// Samples left when the length is limited.
    remaining: Option<u32>,
}

impl Prbs {
    /// A generator seeded with all ones (any non-zero seed gives the same sequence, shifted).
    pub fn new(cfg: PrbsConfig) -> Result<Self, PrbsError> {
        let taps = TAPS.iter().find(|(b, _)| *b == cfg.bits).map(|(_, t)| *t).ok_or(PrbsError::Bits)?;
        if cfg.hold == 0 || !cfg.low.is_finite() || !cfg.high.is_finite() || !(cfg.low < cfg.high) {
            return Err(PrbsError::Levels);
        }
        let mask = if cfg.bits == 16 { u16::MAX } else { (1u16 << cfg.bits) - 1 };
        let mut p = Self { cfg, mask, taps, state: mask, held: 0, bit: false, remaining: None };
        p.bit = p.shift();
        Ok(p)
    }

    /// A generator that yields `length_samples` samples through [`Prbs::next_sample`] and the
    /// [`Iterator`] impl, then ends. ([`Prbs::next_duty`] ignores the length.)
    pub fn with_length(cfg: PrbsConfig, length_samples: u32) -> Result<Self, PrbsError> {
        let mut p = Self::new(cfg)?;
        p.remaining = Some(length_samples);
        Ok(p)
    }

    /// The configuration.
    pub fn config(&self) -> &PrbsConfig {
        &self.cfg
    }

    /// Period in samples, (2ⁿ − 1)·hold.
    pub fn period_samples(&self) -> u32 {
        self.period_bits() * u32::from(self.cfg.hold)
    }

    /// Samples left before a length-limited sequence ends (`None`: endless).
    pub fn remaining(&self) -> Option<u32> {
        self.remaining
    }

    /// The next sample, or `None` once a length-limited sequence is over.
    pub fn next_sample(&mut self) -> Option<f32> {
        match self.remaining {
            Some(0) => None,
            Some(n) => {
                self.remaining = Some(n - 1);
                Some(self.next_duty())
            }
            None => Some(self.next_duty()),
        }
    }

    /// Period of the bit sequence, 2ⁿ − 1.
    pub fn period_bits(&self) -> u32 {
        (1u32 << self.cfg.bits) - 1
    }

    fn shift(&mut self) -> bool {
        // Fibonacci form: the new bit is the parity of the tapped bits.
        let fb = (self.state & self.taps).count_ones() & 1 == 1;
        self.state = ((self.state << 1) | u16::from(fb)) & self.mask;
        fb
    }

    /// The next sample's level (endless: a length set by [`Prbs::with_length`] is not consumed).
    pub fn next_duty(&mut self) -> f32 {
        if self.held >= self.cfg.hold {
            self.bit = self.shift();
            self.held = 0;
        }
        self.held += 1;
        if self.bit {
            self.cfg.high
        } else {
            self.cfg.low
        }
    }
}

impl Iterator for Prbs {
    type Item = f32;

    fn next(&mut self) -> Option<f32> {
        self.next_sample()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_register_is_maximum_length_and_balanced() {
        for bits in 3..=16u8 {
            let mut p = Prbs::new(PrbsConfig { bits, hold: 1, low: 0.0, high: 1.0 }).unwrap();
            let n = p.period_bits() as usize;
            let seq: std::vec::Vec<bool> = (0..2 * n).map(|_| p.next_duty() > 0.5).collect();
            let ones = seq[..n].iter().filter(|b| **b).count();
            assert_eq!(ones, n.div_ceil(2), "{bits} bits: {ones} ones in {n}");
            assert_eq!(&seq[..n], &seq[n..], "{bits} bits: not periodic with 2^n − 1");
            // No shorter period.
            for d in 1..n {
                if n.is_multiple_of(d) {
                    assert_ne!(&seq[..n - d], &seq[d..n], "{bits} bits: period {d}");
                }
            }
        }
    }

    #[test]
    fn hold_repeats_each_bit() {
        let mut p = Prbs::new(PrbsConfig { bits: 7, hold: 3, low: 0.2, high: 0.8 }).unwrap();
        let seq: std::vec::Vec<f32> = (0..300).map(|_| p.next_duty()).collect();
        for chunk in seq.chunks(3) {
            assert!(chunk.iter().all(|x| *x == chunk[0]));
            assert!(chunk[0] == 0.2 || chunk[0] == 0.8);
        }
        let bad = [
            (2, 1, 0.0, 1.0, PrbsError::Bits),
            (7, 0, 0.0, 1.0, PrbsError::Levels),
            (7, 1, 0.9, 0.1, PrbsError::Levels),
            (7, 1, f32::NAN, 0.1, PrbsError::Levels),
        ];
        for (bits, hold, low, high, want) in bad {
            assert_eq!(Prbs::new(PrbsConfig { bits, hold, low, high }).err(), Some(want), "{bits} {hold} {low} {high}");
        }
    }
}
