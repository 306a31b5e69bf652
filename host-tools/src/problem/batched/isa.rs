//! The instruction sets the batched loop runs on, and which of them this CPU has.

use pe_firmware::physics::Real;

/// Which instruction set a [`Batched`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// 256-bit AVX registers (x86-64 with AVX, detected at run time).
    Avx,
    /// 512-bit AVX-512 registers, 8 f64 or 16 f32 lanes (x86-64 with AVX-512F and DQ,
    /// detected at run time).
    Avx512,
    /// Plain arrays of lanes, compiled for the best SIMD the CPU has (AVX-512, AVX2,
    /// AVX, NEON, baseline) and chosen at run time; any target.
    Portable,
}

impl Isa {
    /// `N` lanes of `S` on this instruction set: "f64x4 avx", "f32x8 portable".
    pub(super) fn describe_lanes<S: Real, const N: usize>(self) -> String {
        let isa = match self {
            Isa::Avx => "avx",
            Isa::Avx512 => "avx512",
            Isa::Portable => "portable",
        };
        format!("{}x{N} {isa}", S::NAME)
    }

    /// The best this CPU runs: the widest registers it has.
    pub fn detect() -> Isa {
        Isa::available().last().copied().unwrap_or(Isa::Portable)
    }

    /// The best this CPU runs with registers of at most 256 bits (AVX, else the portable
    /// lanes): for loops over small batches, such as a board's (the built-in scene on
    /// 4x4x4 boards gives each board about 31 elements, cut into up to twelve lists by
    /// batch and kernel), where the 8 f64 or 16 f32 lanes of AVX-512 would mostly be the
    /// padding a short pack repeats.
    pub fn detect_narrow() -> Isa {
        Isa::Avx.or_portable()
    }

    /// `self` if this CPU runs it, else [`Isa::Portable`]: the lane types of an instruction
    /// set are only ever built after this check (the `avx` module's safety).
    pub fn or_portable(self) -> Isa {
        if Isa::available().contains(&self) {
            self
        } else {
            Isa::Portable
        }
    }

    /// The name `PE_ISA` takes for this instruction set.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Avx => "avx",
            Isa::Avx512 => "avx512",
        }
    }

    /// The cap the environment sets: `PE_ISA=portable|avx|avx512` keeps the loops off wider
    /// registers than it names (to measure on an AVX-512 machine what an AVX2 laptop runs:
    /// `PE_ISA=avx`); unset, no cap. A value that names no instruction set is an error
    /// naming the variable and the known values (the command lines check it before work).
    pub fn cap_from_env() -> Result<Option<Isa>, String> {
        let Some(v) = std::env::var_os("PE_ISA") else {
            return Ok(None);
        };
        let v = v.to_string_lossy();
        [Isa::Portable, Isa::Avx, Isa::Avx512]
            .into_iter()
            .find(|i| i.name() == v.trim())
            .map(Some)
            .ok_or_else(|| format!("PE_ISA={v:?}: known values are portable, avx, avx512"))
    }

    /// Every instruction set this CPU runs, narrowest first (the portable lanes always),
    /// none wider than `PE_ISA` allows ([`Self::cap_from_env`]; an invalid value caps
    /// nothing here: the command lines refuse it before work).
    pub fn available() -> Vec<Isa> {
        let cap = Isa::cap_from_env().ok().flatten();
        let mut v = Isa::on_this_cpu();
        if let Some(cap) = cap {
            v.retain(|&i| i.width_rank() <= cap.width_rank());
        }
        v
    }

    /// Narrowest first: the order [`Self::available`] lists and caps by.
    fn width_rank(self) -> u8 {
        match self {
            Isa::Portable => 0,
            Isa::Avx => 1,
            Isa::Avx512 => 2,
        }
    }

    /// Every instruction set this CPU runs, narrowest first.
    fn on_this_cpu() -> Vec<Isa> {
        #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))]
        let mut v = vec![Isa::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx") {
                v.push(Isa::Avx);
            }
            if has!("avx") && has!("avx512f") && has!("avx512dq") {
                v.push(Isa::Avx512);
            }
        }
        v
    }
}
