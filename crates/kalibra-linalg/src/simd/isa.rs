//! [`Isa`]: the instruction sets a batched kernel runs on, chosen at run time.

use std::str::FromStr;

use pulp::{Simd, WithSimd};

use crate::LinalgError;

/// An instruction set a batched kernel runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Isa {
    /// x86-64 AVX-512 (pulp's `V4`): 8 f64 lanes per vector, fused multiply-add.
    Avx512,
    /// x86-64 AVX2 with FMA (pulp's `V3`): 4 lanes per vector, fused multiply-add.
    Avx2,
    /// aarch64 NEON: 2 lanes per vector, fused multiply-add.
    Neon,
    /// No SIMD: one lane at a time, separate multiply and add like the scalar filters.
    Scalar,
}

impl Isa {
    /// Every instruction set, widest first.
    pub const ALL: [Isa; 4] = [Isa::Avx512, Isa::Avx2, Isa::Neon, Isa::Scalar];

    /// The widest instruction set this CPU runs (at run time, not the build's target).
    pub fn detect() -> Isa {
        Self::ALL
            .into_iter()
            .find(|isa| isa.is_available())
            .unwrap_or(Isa::Scalar)
    }

    /// Whether this CPU runs `self`.
    pub fn is_available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => pulp::x86::V4::try_new().is_some(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => pulp::x86::V3::try_new().is_some(),
            #[cfg(target_arch = "aarch64")]
            Isa::Neon => pulp::aarch64::Neon::try_new().is_some(),
            Isa::Scalar => true,
            #[allow(unreachable_patterns)] // Every arm above exists on some target.
            _ => false,
        }
    }

    /// The instruction sets this CPU runs, widest first (the scalar fallback always).
    pub fn available() -> Vec<Isa> {
        Self::ALL.into_iter().filter(|i| i.is_available()).collect()
    }

    /// f64 lanes per vector.
    pub fn lanes(self) -> usize {
        match self {
            Isa::Avx512 => 8,
            Isa::Avx2 => 4,
            Isa::Neon => 2,
            Isa::Scalar => 1,
        }
    }

    /// The lowercase name [`Isa::from_str`](std::str::FromStr) parses.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Avx512 => "avx512",
            Isa::Avx2 => "avx2",
            Isa::Neon => "neon",
            Isa::Scalar => "scalar",
        }
    }

    /// `self` if this CPU runs it.
    ///
    /// # Errors
    /// [`LinalgError::Unsupported`] if it does not.
    pub fn checked(self) -> Result<Isa, LinalgError> {
        if self.is_available() {
            Ok(self)
        } else {
            Err(LinalgError::Unsupported {
                what: match self {
                    Isa::Avx512 => "instruction set avx512 on this CPU",
                    Isa::Avx2 => "instruction set avx2 on this CPU",
                    Isa::Neon => "instruction set neon on this CPU",
                    Isa::Scalar => "the scalar fallback",
                },
            })
        }
    }

    /// Runs `op` with this instruction set's pulp token (the scalar fallback if the CPU does
    /// not have it; constructors check with [`Isa::checked`] first). Studies use it to run
    /// lane-wise model code (truth simulation, Jacobians at the estimates) on the batch's
    /// instruction set, so that every lane-wise result depends on the `Isa` alone.
    ///
    /// ```
    /// use kalibra_linalg::simd::{BATCH, Isa};
    /// use pulp::{Simd, WithSimd};
    ///
    /// struct Double<'a>(&'a mut [f64; BATCH]);
    /// impl WithSimd for Double<'_> {
    ///     type Output = ();
    ///     #[inline(always)]
    ///     fn with_simd<S: Simd>(self, simd: S) {
    ///         let (chunks, _) = S::as_mut_simd_f64s(self.0);
    ///         for c in chunks {
    ///             *c = simd.add_f64s(*c, *c);
    ///         }
    ///     }
    /// }
    /// let mut x = [1.5; BATCH];
    /// Isa::detect().dispatch(Double(&mut x));
    /// assert_eq!(x, [3.0; BATCH]);
    /// ```
    #[inline]
    pub fn dispatch<Op: WithSimd>(self, op: Op) -> Op::Output {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                if let Some(simd) = pulp::x86::V4::try_new() {
                    return Simd::vectorize(simd, op);
                }
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => {
                if let Some(simd) = pulp::x86::V3::try_new() {
                    return Simd::vectorize(simd, op);
                }
            }
            #[cfg(target_arch = "aarch64")]
            Isa::Neon => {
                if let Some(simd) = pulp::aarch64::Neon::try_new() {
                    return Simd::vectorize(simd, op);
                }
            }
            _ => {}
        }
        Simd::vectorize(pulp::Scalar::new(), op)
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Isa {
    type Err = LinalgError;

    /// Parses `avx512`, `avx2`, `neon` or `scalar` (any case, surrounding blanks ignored), or
    /// `auto` (or nothing) for [`Isa::detect`]. The result is checked against the CPU.
    ///
    /// ```
    /// use kalibra_linalg::simd::Isa;
    /// assert_eq!("scalar".parse::<Isa>()?, Isa::Scalar);
    /// assert!("sse9".parse::<Isa>().is_err());
    /// # Ok::<(), kalibra_linalg::LinalgError>(())
    /// ```
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let isa = match text.trim().to_ascii_lowercase().as_str() {
            "" | "auto" => return Ok(Isa::detect()),
            "avx512" | "avx-512" => Isa::Avx512,
            "avx2" => Isa::Avx2,
            "neon" => Isa::Neon,
            "scalar" => Isa::Scalar,
            _ => {
                return Err(LinalgError::UnknownIsa {
                    name: text.to_owned(),
                });
            }
        };
        isa.checked()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instruction_sets_parse_and_are_checked_against_the_cpu() {
        assert_eq!("scalar".parse::<Isa>(), Ok(Isa::Scalar));
        assert_eq!(" AVX2 ".parse::<Isa>().is_ok(), Isa::Avx2.is_available());
        assert_eq!("auto".parse::<Isa>(), Ok(Isa::detect()));
        assert!(matches!(
            "sse9".parse::<Isa>(),
            Err(LinalgError::UnknownIsa { name }) if name == "sse9"
        ));
        for isa in Isa::ALL {
            assert_eq!(isa.name().parse::<Isa>().is_ok(), isa.is_available());
            if !isa.is_available() {
                assert!(matches!(
                    isa.checked(),
                    Err(LinalgError::Unsupported { .. })
                ));
            }
        }
        assert!(Isa::available().contains(&Isa::detect()));
        #[cfg(target_arch = "x86_64")]
        assert!(!Isa::Neon.is_available());
    }
}
