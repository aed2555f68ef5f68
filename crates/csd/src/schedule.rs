//! The DDPM noise schedule of DeepFloyd IF, timestep sampling and `add_noise`.
//!
//! Schedule "squaredcos_cap_v2" (Nichol & Dhariwal's cosine schedule as diffusers builds it), all in `f64`:
//!
//! ```text
//! ᾱ(τ)  = cos²(((τ + 0.008) / 1.008) · π/2),       τ ∈ [0, 1]
//! β_i   = min(1 − ᾱ((i + 1)/T) / ᾱ(i/T), 0.999),   i = 0 … T−1
//! ᾱ_t   = Π_{i ≤ t} (1 − β_i)                       (alphas_cumprod, index t = 0 … T−1)
//! ```
//!
//! Score-distillation weight w(t) = 1 − ᾱ_t. Forward noising z_t = √ᾱ_t · z0 + √(1 − ᾱ_t) · ε.

use crate::GuidanceError;
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// A DDPM noise schedule: `alphas_cumprod[t]` = ᾱ_t for integer timesteps `t ∈ [0, T)`.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseSchedule {
    alphas_cumprod: Vec<f64>,
}

impl NoiseSchedule {
    /// The "squaredcos_cap_v2" schedule with `num_train_timesteps` steps (IF uses 1000).
    pub fn squaredcos_cap_v2(num_train_timesteps: usize) -> Result<Self, GuidanceError> {
        if num_train_timesteps == 0 {
            return Err(GuidanceError::InvalidInput(
                "the noise schedule needs at least one timestep".into(),
            ));
        }
        let alpha_bar = |tau: f64| {
            let c = ((tau + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2).cos();
            c * c
        };
        let n = num_train_timesteps as f64;
        let mut alphas_cumprod = Vec::with_capacity(num_train_timesteps);
        let mut prod = 1.0;
        for i in 0..num_train_timesteps {
            let beta = (1.0 - alpha_bar((i + 1) as f64 / n) / alpha_bar(i as f64 / n)).min(0.999);
            prod *= 1.0 - beta;
            alphas_cumprod.push(prod);
        }
        Ok(Self { alphas_cumprod })
    }

    /// Number of training timesteps T.
    pub fn num_train_timesteps(&self) -> usize {
        self.alphas_cumprod.len()
    }

    /// ᾱ_t for every t (`alphas_cumprod` in diffusers' naming).
    pub fn alphas_cumprod(&self) -> &[f64] {
        &self.alphas_cumprod
    }

    /// ᾱ_t; an error when `t` is outside `[0, T)`.
    pub fn alpha_bar(&self, t: i64) -> Result<f64, GuidanceError> {
        usize::try_from(t)
            .ok()
            .and_then(|i| self.alphas_cumprod.get(i).copied())
            .ok_or_else(|| {
                GuidanceError::InvalidInput(format!(
                    "timestep {t} is outside the schedule's range [0, {})",
                    self.alphas_cumprod.len()
                ))
            })
    }

    /// Score-distillation weight w(t) = 1 − ᾱ_t.
    pub fn weight(&self, t: i64) -> Result<f64, GuidanceError> {
        Ok(1.0 - self.alpha_bar(t)?)
    }

    /// Forward noising of a batch, in place of a new buffer: per sample `b` (the outermost axis,
    /// `z0.len() / timesteps.len()` values each), `z_t = √ᾱ_{t_b} · z0 + √(1 − ᾱ_{t_b}) · ε`.
    /// The two coefficients are computed in `f64` and applied in `f32` (as diffusers does with fp32 tensors).
    pub fn add_noise(
        &self,
        z0: &[f32],
        noise: &[f32],
        timesteps: &[i64],
    ) -> Result<Vec<f32>, GuidanceError> {
        if z0.len() != noise.len() {
            return Err(GuidanceError::InvalidInput(format!(
                "add_noise: {} clean values but {} noise values",
                z0.len(),
                noise.len()
            )));
        }
        if timesteps.is_empty() || !z0.len().is_multiple_of(timesteps.len()) {
            return Err(GuidanceError::InvalidInput(format!(
                "add_noise: {} values cannot be split into {} samples",
                z0.len(),
                timesteps.len()
            )));
        }
        let per_sample = z0.len() / timesteps.len();
        let mut out = vec![0.0f32; z0.len()];
        for (b, &t) in timesteps.iter().enumerate() {
            let a = self.alpha_bar(t)?;
            let (cs, cn) = (a.sqrt() as f32, (1.0 - a).sqrt() as f32);
            let range = b * per_sample..(b + 1) * per_sample;
            for ((o, &z), &e) in out[range.clone()]
                .iter_mut()
                .zip(&z0[range.clone()])
                .zip(&noise[range])
            {
                *o = cs * z + cn * e;
            }
        }
        Ok(out)
    }
}

/// An inclusive range of integer timesteps `[min, max]` from which timesteps are drawn uniformly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimestepRange {
    /// Smallest timestep drawn (IF / reference: 20 = 0.02 · T).
    pub min: i64,
    /// Largest timestep drawn, inclusive (IF / reference: 980 = 0.98 · T).
    pub max: i64,
}

impl Default for TimestepRange {
    fn default() -> Self {
        Self { min: 20, max: 980 }
    }
}

impl TimestepRange {
    /// Checks `0 ≤ min ≤ max < num_train_timesteps`.
    pub fn validate(&self, num_train_timesteps: usize) -> Result<(), GuidanceError> {
        if self.min < 0 || self.min > self.max || self.max >= num_train_timesteps as i64 {
            return Err(GuidanceError::InvalidInput(format!(
                "timestep range [{}, {}] must satisfy 0 ≤ min ≤ max < {num_train_timesteps}",
                self.min, self.max
            )));
        }
        Ok(())
    }

    /// Draws `count` timesteps independently and uniformly from `[min, max]` (one per image).
    pub fn sample(&self, count: usize, rng: &mut dyn RngCore) -> Vec<i64> {
        (0..count)
            .map(|_| rng.random_range(self.min..=self.max))
            .collect()
    }
}

/// Samples per independent noise stream in [`fill_standard_normal`] (even, so pairs never straddle).
pub const NOISE_CHUNK: usize = 1 << 16;

/// Fills a buffer with independent standard normal samples drawn from `rng`.
///
/// Method: 32 bytes are taken from `rng` as the key of a ChaCha8 generator; chunk `k` of
/// [`NOISE_CHUNK`] samples is filled from that generator's stream `k` (so chunks are filled in parallel
/// and the result does not depend on the number of threads). Within a chunk, Marsaglia's polar method in
/// `f64`: each `u64` gives two uniforms u, v ∈ (−1, 1) from its high and low 32 bits, rejected unless
/// 0 < s = u² + v² < 1, then both u·√(−2 ln s / s) and v·√(−2 ln s / s) are used, rounded to `f32`.
/// Deterministic for a given RNG state; the caller's RNG advances by exactly 32 bytes per call.
pub fn fill_standard_normal(out: &mut [f32], rng: &mut dyn RngCore) {
    let mut key = [0u8; 32];
    rng.fill_bytes(&mut key);
    out.par_chunks_mut(NOISE_CHUNK)
        .enumerate()
        .for_each(|(k, chunk)| {
            let mut stream = ChaCha8Rng::from_seed(key);
            stream.set_stream(k as u64);
            let mut pairs = chunk.chunks_exact_mut(2);
            for pair in &mut pairs {
                let (a, b) = polar_pair(&mut stream);
                pair[0] = a as f32;
                pair[1] = b as f32;
            }
            if let [last] = pairs.into_remainder() {
                *last = polar_pair(&mut stream).0 as f32;
            }
        });
}

/// A vector of `len` standard normal samples (see [`fill_standard_normal`]).
pub fn standard_normal(len: usize, rng: &mut dyn RngCore) -> Vec<f32> {
    let mut v = vec![0.0; len];
    fill_standard_normal(&mut v, rng);
    v
}

fn polar_pair(rng: &mut ChaCha8Rng) -> (f64, f64) {
    const SCALE: f64 = 1.0 / (1u64 << 31) as f64;
    loop {
        let bits = rng.next_u64();
        let u = ((bits >> 32) as f64 + 0.5) * SCALE - 1.0;
        let v = ((bits & 0xffff_ffff) as f64 + 0.5) * SCALE - 1.0;
        let s = u * u + v * v;
        if s > 0.0 && s < 1.0 {
            let f = (-2.0 * s.ln() / s).sqrt();
            return (u * f, v * f);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn if_schedule() -> NoiseSchedule {
        NoiseSchedule::squaredcos_cap_v2(1000).expect("T = 1000 is valid")
    }

    #[test]
    fn squaredcos_cap_v2_matches_spec_check_values() {
        let s = if_schedule();
        assert_eq!(s.num_train_timesteps(), 1000);
        // Check values of spec §7 (6 significant digits there).
        for (t, expected, tol) in [
            (20, 0.998114, 1e-6),
            (250, 0.845888, 1e-6),
            (500, 0.492285, 1e-6),
            (980, 8.765e-4, 1e-7),
        ] {
            let a = s.alpha_bar(t).expect("in range");
            assert!(
                (a - expected).abs() < tol,
                "ᾱ_{t} = {a}, expected {expected}"
            );
        }
    }

    #[test]
    fn alphas_cumprod_decrease_strictly_and_stay_in_unit_interval() {
        let s = if_schedule();
        let a = s.alphas_cumprod();
        assert!(a[0] < 1.0 && a[0] > 0.999);
        assert!(a.windows(2).all(|w| w[1] < w[0]));
        assert!(a.iter().all(|&x| x > 0.0 && x < 1.0));
    }

    #[test]
    fn weight_is_one_minus_alpha_bar() {
        let s = if_schedule();
        let a = s.alpha_bar(500).expect("in range");
        assert_eq!(s.weight(500).expect("in range"), 1.0 - a);
    }

    #[test]
    fn out_of_range_timesteps_are_errors() {
        let s = if_schedule();
        assert!(s.alpha_bar(-1).is_err());
        assert!(s.alpha_bar(1000).is_err());
        assert!(s.add_noise(&[0.0; 4], &[0.0; 4], &[1000, 0]).is_err());
        assert!(NoiseSchedule::squaredcos_cap_v2(0).is_err());
    }

    #[test]
    fn add_noise_applies_per_sample_coefficients() {
        let s = if_schedule();
        let z0 = [1.0f32, 2.0, -1.0, 0.5];
        let eps = [0.5f32, -0.5, 2.0, 1.0];
        let t = [100i64, 900];
        let z = s.add_noise(&z0, &eps, &t).expect("valid");
        for i in 0..4 {
            let a = s.alpha_bar(t[i / 2]).expect("in range");
            let expected = a.sqrt() * z0[i] as f64 + (1.0 - a).sqrt() * eps[i] as f64;
            assert!(
                (z[i] as f64 - expected).abs() < 1e-6,
                "{i}: {} vs {expected}",
                z[i]
            );
        }
        assert!(s.add_noise(&z0, &eps[..3], &t).is_err());
        assert!(s.add_noise(&z0, &eps, &[1, 2, 3]).is_err());
    }

    #[test]
    fn timesteps_are_uniform_integers_in_the_inclusive_range() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let range = TimestepRange { min: 20, max: 24 };
        let t = range.sample(50_000, &mut rng);
        let mut counts = [0usize; 5];
        for &x in &t {
            assert!((20..=24).contains(&x));
            counts[(x - 20) as usize] += 1;
        }
        // Each of the 5 values expects 10,000 draws (σ ≈ 89); 5σ bounds.
        assert!(
            counts.iter().all(|&c| c.abs_diff(10_000) < 450),
            "{counts:?}"
        );
    }

    #[test]
    fn timestep_range_validation() {
        assert!(TimestepRange::default().validate(1000).is_ok());
        assert!(TimestepRange { min: 0, max: 999 }.validate(1000).is_ok());
        assert!(TimestepRange { min: 0, max: 1000 }.validate(1000).is_err());
        assert!(TimestepRange { min: -1, max: 10 }.validate(1000).is_err());
        assert!(TimestepRange { min: 11, max: 10 }.validate(1000).is_err());
    }

    #[test]
    fn standard_normal_has_unit_moments_and_is_deterministic() {
        let n = 3 * NOISE_CHUNK + 1; // several streams, and an odd length: exercises the remainder path
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let v = standard_normal(n, &mut rng);
        let mut rng2 = ChaCha8Rng::seed_from_u64(3);
        assert_eq!(v, standard_normal(n, &mut rng2));
        // Streams differ from each other (no repeated chunk).
        assert_ne!(v[..NOISE_CHUNK], v[NOISE_CHUNK..2 * NOISE_CHUNK]);
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
        let var = v.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n as f64;
        let kurt =
            v.iter().map(|&x| (x as f64 - mean).powi(4)).sum::<f64>() / n as f64 / (var * var);
        // Standard errors: mean 1/√n ≈ 0.0022, variance √(2/n) ≈ 0.0032, kurtosis √(24/n) ≈ 0.011.
        assert!(mean.abs() < 0.012, "mean {mean}");
        assert!((var - 1.0).abs() < 0.016, "variance {var}");
        assert!((kurt - 3.0).abs() < 0.06, "kurtosis {kurt}");
        let tail = v.iter().filter(|&&x| x.abs() > 1.959_964).count() as f64 / n as f64;
        assert!((tail - 0.05).abs() < 0.0025, "two-sided 5% tail {tail}");
    }
}
