//! The instruction set the hot kernels run with, chosen at run time.
//!
//! The workspace builds portable binaries (x86-64's baseline, SSE2), so that a study's tasks
//! run the login node's binary on any compute node. The step's kernels (the bond pass, the
//! contact pass with its kick, the drift, the neighbour search) are compiled twice: for the
//! baseline and for AVX2 with FMA, and each call takes the wider one when the CPU has it
//! ([`wide`]; the crate's `kernel!` macro writes each entry point). Results are the same to
//! the bit either way: Rust never fuses a multiply and an add unless the code asks for it
//! (`mul_add`, which the engine does not use), and IEEE 754 fixes the result of every add,
//! multiply, divide and square root whatever the width of the instruction that computes it;
//! the engine test `results_do_not_depend_on_the_instruction_set` runs a scene both ways and
//! compares. A build with `-C target-cpu=native` compiles everything for the build machine
//! and needs none of this.
//!
//! `HVI_ISA=baseline` in the environment keeps the baseline kernels (for comparing the two);
//! [`force`] does the same within a process.
use std::sync::atomic::{AtomicU8, Ordering};

/// The instruction set of the kernels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// x86-64's baseline (SSE2), or whatever the build targets on another architecture.
    Baseline,
    /// AVX2 and FMA (x86-64 only).
    Avx2,
}

impl Isa {
    /// The name printed in a run's summary.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::Avx2 => "avx2",
        }
    }
}

const UNKNOWN: u8 = 0;
const BASELINE: u8 = 1;
const AVX2: u8 = 2;

/// The choice, made once (0: not yet).
static CHOSEN: AtomicU8 = AtomicU8::new(UNKNOWN);

/// The instruction set the kernels run with: AVX2 when the CPU has AVX2 and FMA and
/// `HVI_ISA` is not `baseline` (nor [`force`]d otherwise).
pub fn isa() -> Isa {
    match CHOSEN.load(Ordering::Relaxed) {
        AVX2 => Isa::Avx2,
        BASELINE => Isa::Baseline,
        _ => {
            let isa = detect();
            force(isa);
            isa
        }
    }
}

/// Whether the kernels take their AVX2 form (a relaxed load once the choice is made).
#[inline(always)]
pub fn wide() -> bool {
    match CHOSEN.load(Ordering::Relaxed) {
        AVX2 => true,
        BASELINE => false,
        _ => isa() == Isa::Avx2,
    }
}

/// Sets the instruction set of the kernels from now on, for every thread (falls back to the
/// baseline where the CPU lacks AVX2). Results do not depend on it; only the speed does.
pub fn force(isa: Isa) {
    let code = if isa == Isa::Avx2 && cpu_has_avx2() {
        AVX2
    } else {
        BASELINE
    };
    CHOSEN.store(code, Ordering::Relaxed);
}

/// Whether this CPU can run the AVX2 kernels.
pub fn avx2_available() -> bool {
    cpu_has_avx2()
}

/// What is wrong with the environment's `HVI_ISA`, if anything ([`setting_problem`]).
pub fn env_setting_problem() -> Option<String> {
    setting_problem(std::env::var("HVI_ISA").ok().as_deref())
}

/// What is wrong with a value of `HVI_ISA` (`None`: unset): it takes `baseline` and `avx2` (the
/// default where the CPU has it); another is ignored.
pub fn setting_problem(value: Option<&str>) -> Option<String> {
    let v = value?;
    if v.eq_ignore_ascii_case("baseline") || v.eq_ignore_ascii_case("avx2") {
        return None;
    }
    Some(format!(
        "HVI_ISA = {v:?} is ignored: it takes `baseline` or `avx2` (the kernels run {})",
        isa().name()
    ))
}

fn detect() -> Isa {
    let asked_baseline = std::env::var("HVI_ISA").is_ok_and(|v| v.eq_ignore_ascii_case("baseline"));
    if !asked_baseline && cpu_has_avx2() {
        Isa::Avx2
    } else {
        Isa::Baseline
    }
}

#[cfg(target_arch = "x86_64")]
fn cpu_has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

#[cfg(not(target_arch = "x86_64"))]
fn cpu_has_avx2() -> bool {
    false
}

/// Defines a kernel's entry point `$name`, which calls `$body` (a function of the same
/// arguments, `#[inline(always)]`) compiled with AVX2 and FMA when [`wide`] says so, else as
/// built. The AVX2 copy is a nested function `avx2` of the entry point.
///
/// The body's callees must be `#[inline(always)]` (or small enough to inline) to be compiled
/// for AVX2 with it.
macro_rules! kernel {
    (
        $(#[$meta:meta])*
        fn $name:ident $(<$($g:ident : $bound:path),*>)? ($($arg:ident : $ty:ty),* $(,)?) -> $ret:ty
        = $body:path;
    ) => {
        $(#[$meta])*
        fn $name $(<$($g: $bound),*>)? ($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2,fma")]
                unsafe fn avx2 $(<$($g: $bound),*>)? ($($arg: $ty),*) -> $ret {
                    $body($($arg),*)
                }
                if $crate::simd::wide() {
                    // SAFETY: `wide` is true only when the CPU has AVX2 and FMA.
                    return unsafe { avx2($($arg),*) };
                }
            }
            $body($($arg),*)
        }
    };
}
pub(crate) use kernel;
