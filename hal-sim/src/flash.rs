//! A mock NOR flash that behaves like the STM32L4's, for the persistence tests and `hter
//! virtual-board`: 64-bit double words with ECC, programmed once after an erase (or over with
//! all zeros, which RM0351 allows), bits only 1 → 0, erase sets a page to 0xFF. It can lose power
//! after any number of word programs or page erases. With [`Tear::Ecc`] (the L4) a cut program
//! leaves its double word half programmed and failing its ECC check, and a cut erase leaves
//! every word of the page that held data failing it: the erase acts on the whole page at once,
//! so each programmed cell is left somewhere between its levels, and RM0351 only promises an
//! undefined page. A read covering such a word fails with its address, as the L4's ECCD NMI,
//! noted by the firmware's handler, makes the flash reader fail. With [`Tear::Readable`] the
//! torn word or page reads back half written (flash without ECC, or a tear the ECC happens to
//! miss).

use std::cell::Cell;
use std::rc::Rc;

use embedded_storage_async::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use hter::persist::flash::EccErrors;

/// Flash word of the STM32L4 (double-word programming, 8 ECC bits per double word).
pub const WORD: usize = 8;

/// Why a mock operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MockError {
    /// Power is off (lost at this operation or before).
    PowerLoss,
    /// Outside the flash.
    OutOfBounds,
    /// Not on a word (program) or page (erase) boundary.
    NotAligned,
    /// Programming a word that is not erased with anything but zeros (the L4 sets PROGERR).
    NotErased,
    /// A program or erase in a write-protected flash (the L4's WRPERR: an option byte's WRP
    /// area over the region).
    WriteProtected,
    /// The read covered a double word failing its ECC check, at this offset.
    Ecc(u32),
}

impl NorFlashError for MockError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            MockError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            MockError::NotAligned => NorFlashErrorKind::NotAligned,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// What a power cut leaves in the word or page it interrupts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tear {
    /// The L4: the torn words fail their ECC check.
    Ecc,
    /// Half written and readable.
    Readable,
}

/// Which operation a power cut interrupted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CutIn {
    /// A double-word program.
    Program,
    /// A page erase.
    Erase,
}

/// The mock's ECC-error note: what the firmware's NMI handler leaves for the flash reader.
#[derive(Clone, Default)]
pub struct MockEcc(pub Rc<Cell<Option<u32>>>);

impl EccErrors for MockEcc {
    fn take(&mut self) -> Option<u32> {
        self.0.take()
    }
}

/// The mock flash, `PAGE`-byte pages.
pub struct MockFlash<const PAGE: usize> {
    /// The cells.
    pub bytes: Vec<u8>,
    /// Per double word: fails its ECC check.
    pub torn: Vec<bool>,
    /// What a power cut leaves.
    pub tear: Tear,
    /// A read of a torn word returns its garbage and only notes the error (as the L4 does,
    /// through the NMI) instead of failing itself.
    pub nmi_only: bool,
    /// The ECC-error note the reads leave.
    pub ecc: MockEcc,
    /// Word programs and page erases left before power is lost; `None` = never.
    pub ops_left: Option<usize>,
    /// Power is off: every operation fails until [`MockFlash::power_on`].
    pub dead: bool,
    /// The operation the last power cut interrupted.
    pub cut_in: Option<CutIn>,
    /// Word programs and page erases so far.
    pub ops: usize,
    /// Completed page erases.
    pub erases: usize,
    /// Zero programs over programmed words (repairs).
    pub rewrites: usize,
    /// Every program and erase fails ([`MockError::WriteProtected`]); reads work.
    pub write_protected: bool,
}

impl<const PAGE: usize> MockFlash<PAGE> {
    /// An erased flash of `pages` pages, tearing as the L4 does.
    pub fn blank(pages: usize) -> Self {
        Self::with_tear(pages, Tear::Ecc)
    }

    /// An erased flash of `pages` pages, tearing as `tear` says.
    pub fn with_tear(pages: usize, tear: Tear) -> Self {
        Self {
            bytes: vec![0xFF; pages * PAGE],
            torn: vec![false; pages * PAGE / WORD],
            tear,
            nmi_only: false,
            ecc: MockEcc::default(),
            ops_left: None,
            dead: false,
            cut_in: None,
            ops: 0,
            erases: 0,
            rewrites: 0,
            write_protected: false,
        }
    }

    /// Power back on: operations work again, no cut is pending.
    pub fn power_on(&mut self) {
        self.dead = false;
        self.ops_left = None;
        self.ecc.0.set(None);
    }

    /// Double words failing their ECC check.
    pub fn torn_words(&self) -> usize {
        self.torn.iter().filter(|&&t| t).count()
    }

    /// Spends one operation; `false` if power is lost at this one.
    /// Loses power after `n` more word programs or page erases.
    pub fn cut_after(&mut self, n: usize) {
        self.ops_left = Some(n);
    }

    /// Whether power is off.
    pub fn is_dead(&self) -> bool {
        self.dead
    }

    fn spend(&mut self, what: CutIn) -> bool {
        self.ops += 1;
        match &mut self.ops_left {
            Some(0) => {
                self.dead = true;
                self.cut_in = Some(what);
                false
            }
            Some(n) => {
                *n -= 1;
                true
            }
            None => true,
        }
    }
}

impl<const PAGE: usize> ErrorType for MockFlash<PAGE> {
    type Error = MockError;
}

impl<const PAGE: usize> ReadNorFlash for MockFlash<PAGE> {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), MockError> {
        if self.dead {
            return Err(MockError::PowerLoss);
        }
        let from = offset as usize;
        let src = self.bytes.get(from..from + bytes.len()).ok_or(MockError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        let words = from / WORD..(from + bytes.len()).div_ceil(WORD);
        if let Some(w) = words.clone().find(|&w| self.torn[w]) {
            let at = (w * WORD) as u32;
            self.ecc.0.set(Some(at));
            if !self.nmi_only {
                return Err(MockError::Ecc(at));
            }
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl<const PAGE: usize> NorFlash for MockFlash<PAGE> {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), MockError> {
        let (from, to) = (from as usize, to as usize);
        if !from.is_multiple_of(PAGE) || !to.is_multiple_of(PAGE) || from > to {
            return Err(MockError::NotAligned);
        }
        if to > self.bytes.len() {
            return Err(MockError::OutOfBounds);
        }
        if self.write_protected {
            return Err(MockError::WriteProtected);
        }
        for page in (from..to).step_by(PAGE) {
            if self.dead {
                return Err(MockError::PowerLoss);
            }
            if !self.spend(CutIn::Erase) {
                match self.tear {
                    Tear::Ecc => {
                        for w in page / WORD..(page + PAGE) / WORD {
                            if self.bytes[w * WORD..(w + 1) * WORD].iter().any(|&b| b != 0xFF) {
                                self.torn[w] = true;
                            }
                        }
                    }
                    Tear::Readable => self.bytes[page..page + PAGE / 2].fill(0xFF),
                }
                return Err(MockError::PowerLoss);
            }
            self.bytes[page..page + PAGE].fill(0xFF);
            self.torn[page / WORD..(page + PAGE) / WORD].fill(false);
            self.erases += 1;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, data: &[u8]) -> Result<(), MockError> {
        let from = offset as usize;
        if !from.is_multiple_of(WORD) || !data.len().is_multiple_of(WORD) {
            return Err(MockError::NotAligned);
        }
        if from + data.len() > self.bytes.len() {
            return Err(MockError::OutOfBounds);
        }
        if self.write_protected {
            return Err(MockError::WriteProtected);
        }
        for (i, word) in data.chunks(WORD).enumerate() {
            if self.dead {
                return Err(MockError::PowerLoss);
            }
            let at = from + i * WORD;
            let zeros = word.iter().all(|&b| b == 0);
            // The L4 programs a non-erased double word only with all zeros (whose ECC is zero:
            // a torn word so programmed reads again).
            let torn = self.torn[at / WORD];
            if torn || self.bytes[at..at + WORD].iter().any(|&b| b != 0xFF) {
                if !zeros {
                    return Err(MockError::NotErased);
                }
                if !torn {
                    self.rewrites += 1;
                }
            }
            let powered = self.spend(CutIn::Program);
            let programmed = if powered { WORD } else { WORD / 2 };
            for (c, w) in self.bytes[at..at + WORD].iter_mut().zip(word).take(programmed) {
                *c &= w;
            }
            if !powered {
                if self.tear == Tear::Ecc {
                    self.torn[at / WORD] = true;
                }
                return Err(MockError::PowerLoss);
            }
            self.torn[at / WORD] = false;
        }
        Ok(())
    }
}
