//! Run-time SIMD dispatch of the per-pixel loops.

/// Runs `op` compiled for the widest SIMD instruction set the CPU has (AVX2 and FMA on x86-64
/// where present, detected at run time, safely, by `pulp`; the baseline otherwise). The per-pixel
/// shading and its Jacobian are scalar f64 code; compiled with AVX2 it gets the three-operand VEX
/// forms and wider packing of the vector arithmetic. The results do not depend on which set runs:
/// Rust never contracts a multiply and an add into a fused multiply–add, so every operation is
/// the same IEEE operation (tested bit for bit against the baseline build of the same loops).
///
/// The kernel's `with_simd` must call `#[inline(always)]` code only: anything not inlined is
/// compiled once, for the baseline instruction set.
#[inline(always)]
pub(crate) fn dispatch<Op: pulp::WithSimd>(op: Op) -> Op::Output {
    pulp::Arch::new().dispatch(op)
}
