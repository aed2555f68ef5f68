//! Adam (Kingma & Ba) exactly as `torch.optim.Adam` computes it with default flags.

use serde::{Deserialize, Serialize};

/// Hyper-parameters of [`Adam`]. The defaults are the reference's (spec §5).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    /// Learning rate (step size), default `0.002`.
    pub lr: f64,
    /// Decay of the first-moment estimate, default `0.9`.
    pub beta1: f64,
    /// Decay of the second-moment estimate, default `0.999`.
    pub beta2: f64,
    /// Added to `sqrt(v̂)` in the denominator, default `1e-8`.
    pub eps: f64,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 0.002,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// The optimizer's state: moments and the step counter. Plain data, for checkpoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamState {
    /// Number of steps taken so far (the `t` of the bias correction; the next step uses `t + 1`).
    pub step: u64,
    /// First-moment estimate `m`, one entry per parameter.
    pub m: Vec<f64>,
    /// Second-moment estimate `v` (of the squared gradient), one entry per parameter.
    pub v: Vec<f64>,
}

/// Errors from [`Adam`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AdamError {
    /// The parameter or gradient length differs from the optimizer's.
    #[error("length mismatch: optimizer has {expected} parameters, got {got}")]
    LengthMismatch {
        /// Number of parameters the optimizer was built for.
        expected: usize,
        /// Length that was passed.
        got: usize,
    },
    /// A gradient entry is NaN or infinite; nothing was changed.
    #[error("non-finite gradient at index {index} ({value})")]
    NonFiniteGradient {
        /// First offending index.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A hyper-parameter is out of its domain.
    #[error("invalid Adam hyper-parameter: {0}")]
    InvalidConfig(String),
}

/// Adam with bias correction by step count, no weight decay, no AMSGrad.
///
/// One step with gradient `g` (element-wise, `t` the new step count):
/// ```text
/// m ← β1·m + (1 − β1)·g
/// v ← β2·v + (1 − β2)·g²
/// θ ← θ − lr · (m / (1 − β1^t)) / (sqrt(v / (1 − β2^t)) + ε)
/// ```
/// which is what `torch.optim.Adam` computes (it folds the corrections into the step size and the
/// denominator; the result is the same up to rounding). The first step therefore moves every
/// coordinate by `lr · g/(|g| + ε)`, i.e. `lr · sign(g)` for `|g| ≫ ε`.
#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    config: AdamConfig,
    state: AdamState,
}

impl Adam {
    /// A fresh optimizer for `len` parameters (zero moments, step 0).
    pub fn new(len: usize, config: AdamConfig) -> Result<Self, AdamError> {
        validate(&config)?;
        Ok(Self {
            config,
            state: AdamState {
                step: 0,
                m: vec![0.0; len],
                v: vec![0.0; len],
            },
        })
    }

    /// Restores an optimizer from a saved state (e.g. a checkpoint).
    pub fn from_state(config: AdamConfig, state: AdamState) -> Result<Self, AdamError> {
        validate(&config)?;
        if state.m.len() != state.v.len() {
            return Err(AdamError::LengthMismatch {
                expected: state.m.len(),
                got: state.v.len(),
            });
        }
        if let Some((index, &value)) = state
            .m
            .iter()
            .chain(&state.v)
            .enumerate()
            .find(|(_, x)| !x.is_finite())
        {
            return Err(AdamError::InvalidConfig(format!(
                "saved moment {index} is not finite ({value})"
            )));
        }
        Ok(Self { config, state })
    }

    /// Hyper-parameters.
    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// Changes the learning rate (the moments are kept).
    pub fn set_lr(&mut self, lr: f64) -> Result<(), AdamError> {
        let config = AdamConfig { lr, ..self.config };
        validate(&config)?;
        self.config = config;
        Ok(())
    }

    /// Current state (moments and step count).
    pub fn state(&self) -> &AdamState {
        &self.state
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.state.m.len()
    }

    /// True when the optimizer has no parameters.
    pub fn is_empty(&self) -> bool {
        self.state.m.is_empty()
    }

    /// Takes one step in place. On error nothing is modified.
    pub fn step(&mut self, params: &mut [f64], grad: &[f64]) -> Result<(), AdamError> {
        let n = self.len();
        for got in [params.len(), grad.len()] {
            if got != n {
                return Err(AdamError::LengthMismatch { expected: n, got });
            }
        }
        if let Some((index, &value)) = grad.iter().enumerate().find(|(_, g)| !g.is_finite()) {
            return Err(AdamError::NonFiniteGradient { index, value });
        }
        let AdamConfig {
            lr,
            beta1,
            beta2,
            eps,
        } = self.config;
        self.state.step += 1;
        // Exponents beyond i32 make the corrections exactly 1 anyway.
        let t = i32::try_from(self.state.step).unwrap_or(i32::MAX);
        let correction1 = 1.0 - beta1.powi(t);
        let correction2 = 1.0 - beta2.powi(t);
        for i in 0..n {
            let g = grad[i];
            let m = beta1 * self.state.m[i] + (1.0 - beta1) * g;
            let v = beta2 * self.state.v[i] + (1.0 - beta2) * g * g;
            self.state.m[i] = m;
            self.state.v[i] = v;
            params[i] -= lr * (m / correction1) / ((v / correction2).sqrt() + eps);
        }
        Ok(())
    }
}

fn validate(c: &AdamConfig) -> Result<(), AdamError> {
    let bad = |what: &str, v: f64| Err(AdamError::InvalidConfig(format!("{what} = {v}")));
    if !(c.lr.is_finite() && c.lr >= 0.0) {
        return bad("lr must be finite and >= 0, got lr", c.lr);
    }
    if !(0.0..1.0).contains(&c.beta1) {
        return bad("beta1 must be in [0, 1), got beta1", c.beta1);
    }
    if !(0.0..1.0).contains(&c.beta2) {
        return bad("beta2 must be in [0, 1), got beta2", c.beta2);
    }
    if !(c.eps.is_finite() && c.eps > 0.0) {
        return bad("eps must be finite and > 0, got eps", c.eps);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn adam(len: usize, lr: f64) -> Adam {
        Adam::new(
            len,
            AdamConfig {
                lr,
                ..AdamConfig::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn first_step_moves_each_coordinate_by_lr_times_sign_of_gradient() {
        let mut opt = adam(4, 0.002);
        let mut x = vec![1.0, -2.0, 0.5, 3.0];
        let g = [10.0, -0.3, 1e-3, -7e4];
        opt.step(&mut x, &g).unwrap_or_else(|e| panic!("{e}"));
        let expected = [1.0 - 0.002, -2.0 + 0.002, 0.5 - 0.002, 3.0 + 0.002];
        for i in 0..4 {
            // Exact: lr·g/(|g| + ε); differs from lr·sign(g) by lr·ε/|g|.
            let exact = 0.002 * g[i] / (g[i].abs() + 1e-8);
            assert!((x[i] - (expected[i] + 0.002 * g[i].signum() - exact)).abs() < 1e-15);
            let eps_effect = 0.002 * 1e-8 / g[i].abs();
            assert!(
                (x[i] - expected[i]).abs() <= eps_effect + 1e-15,
                "coordinate {i}: {}",
                x[i]
            );
        }
    }

    #[test]
    fn zero_gradient_leaves_parameters_unchanged() {
        let mut opt = adam(2, 0.1);
        let mut x = vec![0.25, -4.0];
        opt.step(&mut x, &[0.0, 0.0])
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(x, vec![0.25, -4.0]);
    }

    #[test]
    fn second_step_matches_hand_derived_closed_form() {
        // Scalar, g1 then g2. m1 = 0.1 g1, v1 = 0.001 g1²; m2 = 0.09 g1 + 0.1 g2,
        // v2 = 0.000999 g1² + 0.001 g2²; m̂2 = m2/0.19, v̂2 = v2/0.001999.
        let (g1, g2, lr) = (0.5_f64, -2.0_f64, 0.01);
        let mut opt = adam(1, lr);
        let mut x = vec![0.0];
        opt.step(&mut x, &[g1]).unwrap_or_else(|e| panic!("{e}"));
        opt.step(&mut x, &[g2]).unwrap_or_else(|e| panic!("{e}"));
        let step1 = lr * g1 / (g1.abs() + 1e-8);
        let m_hat = (0.09 * g1 + 0.1 * g2) / 0.19;
        let v_hat = (0.000999 * g1 * g1 + 0.001 * g2 * g2) / 0.001999;
        let step2 = lr * m_hat / (v_hat.sqrt() + 1e-8);
        assert!(
            (x[0] - (-step1 - step2)).abs() < 1e-14,
            "{} vs {}",
            x[0],
            -step1 - step2
        );
        assert_eq!(opt.state().step, 2);
    }

    #[test]
    fn constant_gradient_steps_are_lr_sized_every_step() {
        // With a constant gradient, m̂ = g and v̂ = g² exactly at every t (bias correction).
        let mut opt = adam(1, 0.003);
        let mut x = vec![0.0];
        for t in 1..=50 {
            opt.step(&mut x, &[4.0]).unwrap_or_else(|e| panic!("{e}"));
            let expected = -0.003 * f64::from(t) * 4.0 / (4.0 + 1e-8);
            assert!(
                (x[0] - expected).abs() < 1e-12,
                "t = {t}: {} vs {expected}",
                x[0]
            );
        }
    }

    #[test]
    fn restored_state_continues_identically() {
        let grads: Vec<[f64; 2]> = (0..10)
            .map(|k| [f64::from(k).sin(), f64::from(k).cos() * 3.0])
            .collect();
        let mut a = adam(2, 0.01);
        let mut xa = vec![1.0, 2.0];
        for g in &grads {
            a.step(&mut xa, g).unwrap_or_else(|e| panic!("{e}"));
        }
        let mut b = adam(2, 0.01);
        let mut xb = vec![1.0, 2.0];
        for g in &grads[..4] {
            b.step(&mut xb, g).unwrap_or_else(|e| panic!("{e}"));
        }
        let saved = b.state().clone();
        let mut c = Adam::from_state(*b.config(), saved).unwrap_or_else(|e| panic!("{e}"));
        for g in &grads[4..] {
            c.step(&mut xb, g).unwrap_or_else(|e| panic!("{e}"));
        }
        assert_eq!(xa, xb);
        assert_eq!(a.state(), c.state());
    }

    #[test]
    fn non_finite_gradient_is_rejected_without_changing_anything() {
        let mut opt = adam(2, 0.01);
        let mut x = vec![1.0, 2.0];
        let err = opt.step(&mut x, &[1.0, f64::NAN]).err();
        assert!(matches!(
            err,
            Some(AdamError::NonFiniteGradient { index: 1, .. })
        ));
        assert_eq!(x, vec![1.0, 2.0]);
        assert_eq!(opt.state().step, 0);
        assert!(opt.step(&mut x, &[f64::INFINITY, 0.0]).is_err());
    }

    #[test]
    fn length_mismatch_is_an_error() {
        let mut opt = adam(2, 0.01);
        let mut x = vec![1.0, 2.0, 3.0];
        assert!(matches!(
            opt.step(&mut x, &[0.0, 0.0, 0.0]),
            Err(AdamError::LengthMismatch {
                expected: 2,
                got: 3
            })
        ));
    }

    #[test]
    fn invalid_hyper_parameters_are_rejected() {
        for c in [
            AdamConfig {
                lr: -1.0,
                ..AdamConfig::default()
            },
            AdamConfig {
                lr: f64::NAN,
                ..AdamConfig::default()
            },
            AdamConfig {
                beta1: 1.0,
                ..AdamConfig::default()
            },
            AdamConfig {
                beta2: -0.1,
                ..AdamConfig::default()
            },
            AdamConfig {
                eps: 0.0,
                ..AdamConfig::default()
            },
        ] {
            assert!(Adam::new(1, c).is_err(), "{c:?}");
        }
    }

    #[test]
    fn default_config_is_the_reference() {
        assert_eq!(
            AdamConfig::default(),
            AdamConfig {
                lr: 0.002,
                beta1: 0.9,
                beta2: 0.999,
                eps: 1e-8
            }
        );
    }
}
