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

/// Samples per independent noise stream in [`fill_standard_normal`].
pub const NOISE_CHUNK: usize = 1 << 16;

/// Fills a buffer with independent standard normal samples drawn from `rng`.
///
/// Method: 32 bytes are taken from `rng` as the key of a ChaCha8 generator; chunk `k` of
/// [`NOISE_CHUNK`] samples is filled from that generator's stream `k` (so chunks are filled in parallel
/// and the result does not depend on the number of threads). Within a chunk, each sample is drawn with
/// Marsaglia and Tsang's ziggurat ([`Ziggurat`]: 256 layers, one 32-bit word of the key stream per
/// sample: the high 24 bits are the signed abscissa, the low 8 bits the layer, so the two are
/// independent — the fix of Doornik (2005) for the original's correlated bits), rounded to `f32`.
/// Deterministic for a given RNG state; the caller's RNG advances by exactly 32 bytes per call.
///
/// The stream changed twice: from the Marsaglia polar method to the ziggurat on 2026-11-30 (same
/// distribution, about 3× faster), and from 128 layers and one 64-bit word per sample (32-bit
/// abscissa) to 256 layers and one 32-bit word on 2026-12-01 (half the key stream, half the slow
/// path's wedge tests; the samples lie on a grid of x_i / 2²³, at most two `f32` ulps at the widest
/// layer, x_i ≤ 3.65, before the rounding to `f32`). Nothing stores or compares noise values across
/// versions; a seed reproduces a run only with the same version.
pub fn fill_standard_normal(out: &mut [f32], rng: &mut dyn RngCore) {
    let mut key = [0u8; 32];
    rng.fill_bytes(&mut key);
    let zig = Ziggurat::get();
    out.par_chunks_mut(NOISE_CHUNK)
        .enumerate()
        .for_each(|(k, chunk)| {
            let mut stream = ChaCha8Rng::from_seed(key);
            stream.set_stream(k as u64);
            zig.fill(chunk, &mut WordBuffer::new(stream));
        });
}

/// A ChaCha8 stream read one 32-bit word at a time out of a block of [`WordBuffer::WORDS`] words
/// generated at once: the same words, in the same order, as successive `next_u32` calls on the
/// stream (both read the key stream's 32-bit words in order), without the generator's per-call
/// bookkeeping.
struct WordBuffer {
    stream: ChaCha8Rng,
    words: [u32; Self::WORDS],
    /// Index of the next unread word; `WORDS` when the block is used up.
    next: usize,
}

impl WordBuffer {
    const WORDS: usize = 256;

    fn new(stream: ChaCha8Rng) -> Self {
        Self {
            stream,
            words: [0; Self::WORDS],
            next: Self::WORDS,
        }
    }

    /// Generates the next block.
    fn refill(&mut self) {
        // `Rng::fill` on `[u32]`: the stream's bytes, each word read little-endian.
        self.stream.fill(&mut self.words[..]);
        self.next = 0;
    }

    /// The unread words of the current block, refilled first when it is used up.
    fn unread(&mut self) -> &[u32] {
        if self.next == Self::WORDS {
            self.refill();
        }
        &self.words[self.next..]
    }

    #[inline]
    fn next_u32(&mut self) -> u32 {
        if self.next == Self::WORDS {
            self.refill();
        }
        let w = self.words[self.next];
        self.next += 1;
        w
    }
}

/// A vector of `len` standard normal samples (see [`fill_standard_normal`]).
pub fn standard_normal(len: usize, rng: &mut dyn RngCore) -> Vec<f32> {
    let mut v = vec![0.0; len];
    fill_standard_normal(&mut v, rng);
    v
}

/// Marsaglia and Tsang's ziggurat for the standard normal ("The Ziggurat Method for Generating Random
/// Variables", J. Stat. Software 5(8), 2000) with 256 layers, tables built in `f64` from
/// R = 3.6541528853610088 (start of the tail) and v = 4.928673233974658e-3 (area of each layer:
/// R·f(R) + ∫_R^∞ f, so that the top layer closes, x_1·(1 − f(x_1)) = v, to 1.4e-13 relative).
///
/// With f(x) = exp(−x²/2): layers 1…255 are rectangles of half-width x_i, x_255 = R and
/// x_{i−1} = f⁻¹(v / x_i + f(x_i)) (narrower towards the peak; layer 1 is the top); layer 0 is the base
/// strip plus the tail, of virtual half-width x_0 = v / f(R). A sample takes one 32-bit word: j = its
/// high 24 bits, signed (−2²³ ≤ j < 2²³), and the layer i = its low 8 bits; x = j · x_i / 2²³ is
/// accepted at once when |j| < k_i = 2²³ · x_{i−1} / x_i (k_0 = 2²³ · R / x_0, k_1 = 0; 98.5 % of
/// draws, against 97.2 % with 128 layers); otherwise the wedge test `f_i + U·(f_{i−1} − f_i) < f(x)`
/// (f_0 = 1), or for layer 0 Marsaglia's tail algorithm, decides.
#[derive(Debug)]
pub struct Ziggurat {
    /// k_i: acceptance bounds on |j|.
    k: [u32; ZIG_LAYERS],
    /// w_i = x_i / 2²³.
    w: [f64; ZIG_LAYERS],
    /// f_i = f(x_i).
    f: [f64; ZIG_LAYERS],
}

/// A word's low `ZIG_LAYER_BITS` bits pick one of the [`Ziggurat`]'s `ZIG_LAYERS` layers; its
/// other bits are the signed abscissa j, |j| ≤ `ZIG_ABSCISSA_SCALE`.
const ZIG_LAYER_BITS: u32 = 8;
const ZIG_LAYERS: usize = 1 << ZIG_LAYER_BITS;
const ZIG_ABSCISSA_SCALE: u32 = 1 << (31 - ZIG_LAYER_BITS);
const ZIG_R: f64 = 3.654_152_885_361_009;
const ZIG_V: f64 = 4.928_673_233_974_658e-3;

impl Ziggurat {
    fn build() -> Self {
        let m = f64::from(ZIG_ABSCISSA_SCALE); // 2²³
        let last = ZIG_LAYERS - 1;
        let mut k = [0u32; ZIG_LAYERS];
        let mut w = [0.0f64; ZIG_LAYERS];
        let mut f = [0.0f64; ZIG_LAYERS];
        let mut d = ZIG_R;
        let mut t = d;
        let q = ZIG_V / (-0.5 * d * d).exp();
        k[0] = ((d / q) * m) as u32;
        k[1] = 0;
        w[0] = q / m;
        w[last] = d / m;
        f[0] = 1.0;
        f[last] = (-0.5 * d * d).exp();
        for i in (1..last).rev() {
            d = (-2.0 * (ZIG_V / d + (-0.5 * d * d).exp()).ln()).sqrt();
            k[i + 1] = ((d / t) * m) as u32;
            t = d;
            f[i] = (-0.5 * d * d).exp();
            w[i] = d / m;
        }
        Self { k, w, f }
    }

    /// The tables (built once per process).
    pub fn get() -> &'static Self {
        static TABLES: std::sync::OnceLock<Ziggurat> = std::sync::OnceLock::new();
        TABLES.get_or_init(Self::build)
    }

    /// One standard normal sample.
    #[inline]
    pub fn sample(&self, rng: &mut ChaCha8Rng) -> f64 {
        self.sample_from(|| rng.next_u32())
    }

    /// One sample from a source of random words.
    #[inline]
    fn sample_from(&self, mut next: impl FnMut() -> u32) -> f64 {
        loop {
            let bits = next();
            if let Some(x) = self.accept_at_once(bits) {
                return x;
            }
            let (j, i) = Self::split(bits);
            if let Some(x) = self.slow(&mut next, j, i) {
                return x;
            }
        }
    }

    /// Fills `out` with samples, rounded to `f32`, drawn from `words`: the values that
    /// [`Ziggurat::sample`] would draw, in order, from the same stream of words.
    fn fill(&self, out: &mut [f32], words: &mut WordBuffer) {
        let mut filled = 0;
        while filled < out.len() {
            // The common case, in a loop over the block's unread words: each accepted at once
            // gives the next sample.
            let unread = words.unread();
            let take = unread.len().min(out.len() - filled);
            let mut used = 0;
            for (o, &bits) in out[filled..filled + take].iter_mut().zip(unread) {
                match self.accept_at_once(bits) {
                    Some(x) => *o = x as f32,
                    None => break,
                }
                used += 1;
            }
            filled += used;
            words.next += used;
            if used < take {
                // A word not accepted at once (still unread): that sample from the words on.
                let x = self.sample_from(|| words.next_u32());
                out[filled] = x as f32;
                filled += 1;
            }
        }
    }

    /// (j, i): the signed abscissa (high 24 bits, −2²³ ≤ j < 2²³) and the layer (low 8 bits) of
    /// one word.
    #[inline]
    fn split(bits: u32) -> (i32, usize) {
        (
            (bits as i32) >> ZIG_LAYER_BITS,
            (bits % ZIG_LAYERS as u32) as usize,
        )
    }

    /// x = j · w_i when |j| < k_i (98.5 % of words), else None.
    #[inline]
    fn accept_at_once(&self, bits: u32) -> Option<f64> {
        let (j, i) = Self::split(bits);
        (j.unsigned_abs() < self.k[i]).then(|| f64::from(j) * self.w[i])
    }

    /// The rare cases: the tail (layer 0) and the wedges, drawing further words from `next`; None
    /// means "draw again".
    #[cold]
    fn slow(&self, mut next: impl FnMut() -> u32, j: i32, i: usize) -> Option<f64> {
        let mut uniform = || {
            // 53 random bits from two words (32 + the high 21): (0, 1], never 0, so ln is finite.
            let bits = (u64::from(next()) << 21) | u64::from(next() >> 11);
            (bits as f64 + 1.0) * (1.0 / (1u64 << 53) as f64)
        };
        if i == 0 {
            // Marsaglia (1964): x = −ln(U₁)/R, y = −ln(U₂), accept when 2y ≥ x².
            loop {
                let x = -uniform().ln() / ZIG_R;
                let y = -uniform().ln();
                if y + y >= x * x {
                    return Some(if j > 0 { ZIG_R + x } else { -ZIG_R - x });
                }
            }
        }
        let x = f64::from(j) * self.w[i];
        let fx = (-0.5 * x * x).exp();
        (self.f[i] + uniform() * (self.f[i - 1] - self.f[i]) < fx).then_some(x)
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

    #[test]
    fn buffered_fill_draws_what_sample_draws_from_each_stream() {
        // `fill_standard_normal` reads its words through `WordBuffer` and `Ziggurat::fill`; the
        // reference is `Ziggurat::sample` called on each chunk's ChaCha8 stream directly. Three
        // chunks and a remainder: ~2k rejected words (tail and wedges), many of them at block ends.
        let n = 3 * NOISE_CHUNK + 1000;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut key = [0u8; 32];
        rng.clone().fill_bytes(&mut key);
        let got = standard_normal(n, &mut rng);
        let zig = Ziggurat::get();
        let mut rejected = 0;
        for (k, chunk) in got.chunks(NOISE_CHUNK).enumerate() {
            let mut stream = ChaCha8Rng::from_seed(key);
            stream.set_stream(k as u64);
            let mut probe = stream.clone();
            for (m, &v) in chunk.iter().enumerate() {
                assert_eq!(
                    v.to_bits(),
                    (zig.sample(&mut stream) as f32).to_bits(),
                    "chunk {k}, {m}"
                );
            }
            rejected += (0..chunk.len())
                .filter(|_| zig.accept_at_once(probe.next_u32()).is_none())
                .count();
        }
        assert!(rejected > 1000, "{rejected} rejected words");
    }

    #[test]
    fn ziggurat_tables_close_at_the_top_layer() {
        // R and v fix every layer through x_{i−1} = f⁻¹(v / x_i + f(x_i)); they are consistent when
        // the top layer, a rectangle of half-width x_1 under f = 1, has area v: x_1 (1 − f(x_1)) = v.
        let zig = Ziggurat::get();
        let x1 = zig.w[1] * f64::from(ZIG_ABSCISSA_SCALE);
        let area = x1 * (1.0 - (-0.5 * x1 * x1).exp());
        assert!(
            (area / ZIG_V - 1.0).abs() < 1e-11,
            "top layer area {area}, v {ZIG_V}"
        );
        // Widths grow towards the tail, and every acceptance bound is below the abscissa's range.
        assert!(zig.w[1..].windows(2).all(|w| w[0] < w[1]));
        assert!(zig.k.iter().all(|&k| k < ZIG_ABSCISSA_SCALE));
    }

    /// Φ(x) for the CDF test (Abramowitz–Stegun 7.1.26 erf, |error| < 1.5e-7).
    fn normal_cdf(x: f64) -> f64 {
        let z = x.abs() / std::f64::consts::SQRT_2;
        let t = 1.0 / (1.0 + 0.327_591_1 * z);
        let poly = t
            * (0.254_829_592
                + t * (-0.284_496_736
                    + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
        let erf = 1.0 - poly * (-z * z).exp();
        0.5 * (1.0 + if x < 0.0 { -erf } else { erf })
    }

    #[test]
    fn standard_normal_matches_the_normal_cdf_everywhere_including_the_tails() {
        // 4M samples: the empirical CDF at each point, including the ziggurat's layer edges, its
        // tail start R = 3.65 and beyond, agrees with Φ within 5 standard errors √(p(1−p)/n).
        let n = 1usize << 22;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut v = standard_normal(n, &mut rng);
        v.sort_by(f32::total_cmp);
        let mut points: Vec<f64> = (-50..=50).map(|i| f64::from(i) * 0.1).collect();
        points.extend([ZIG_R, -ZIG_R, 3.6, -3.6, 4.0, -4.0]);
        for x in points {
            let p = normal_cdf(x);
            let below = v.partition_point(|&s| f64::from(s) < x) as f64 / n as f64;
            let se = (p * (1.0 - p) / n as f64).sqrt().max(1.0 / n as f64);
            assert!(
                (below - p).abs() < 5.0 * se + 2e-7,
                "P(X < {x}) = {below}, Φ = {p}, {:.1} standard errors",
                (below - p) / se
            );
        }
        // The tail beyond R is reached (~ n · 2.9e-4 samples) and is finite.
        assert!(v.iter().all(|x| x.is_finite()));
        assert!(v.iter().filter(|x| x.abs() > 3.6).count() > 400);
    }
}
