//! The observer's tuning ([`ObserverConfig`]) and its errors ([`ObserverError`]).

use super::STATES;
use crate::params::BenchParams;
use crate::scalar::Real;
use crate::BenchError;

/// How far the pressure transmitter's lag may be from the one [`ObserverConfig::paper`]
/// models (20 ms), s (1 σ).
pub const PAPER_PRESSURE_LAG_SD_S: f64 = 0.040;

/// Tuning of the observer. Noise densities are per second of the random walk (variance grows
/// by `psd · dt`); standard deviations in the state's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverConfig<T> {
    /// The model: the paper's white-box bench by default.
    pub params: BenchParams<T>,
    /// Pressure transmitter's first-order lag, s (≥ 0).
    pub pressure_lag_s: T,
    /// Flow transmitter's first-order lag, s (≥ 0).
    pub flow_lag_s: T,
    /// How far the pressure transmitter's lag may be from `pressure_lag_s`, s (1 σ): while
    /// pressure moves at r mca/s its reading's variance grows by (this · r)².
    pub pressure_lag_sd_s: T,
    /// How far the flow transmitter's lag may be from `flow_lag_s`, s (1 σ), likewise.
    pub flow_lag_sd_s: T,
    /// The drive's torque loop: the electromagnetic torque follows Te(u) through a
    /// first-order lag of this time constant, s (≥ 0).
    pub drive_lag_s: T,
    /// How far the drive's lag may be from `drive_lag_s`, s (1 σ): a torque that changes by
    /// ΔTe over a step adds (K · this · ΔTe)² to the speed's variance (K in rpm/s per %).
    pub drive_lag_sd_s: T,
    /// Water-column inertia L, mca·s²/l (≥ 0): the flow follows the flow balance's root Q*
    /// with the time constant `L / |∂g/∂Q|` (g the flow balance, in mca).
    pub water_inertia: T,
    /// How far the inertia may be from `water_inertia`, mca·s²/l (1 σ): adds the flow's
    /// rate times the time constant it makes to the flow's and the readings' variances.
    pub water_inertia_sd: T,
    /// Process noise of speed, rpm²/s (model error of the torque balance).
    pub speed_psd: T,
    /// Random walk of k2, (mca^½·s/l)²/s.
    pub k2_psd: T,
    /// Random walk of the head scale, 1/s.
    pub head_scale_psd: T,
    /// Random walk of the load-torque scale, 1/s.
    pub torque_scale_psd: T,
    /// Process noise of the lagged readings, (unit)²/s (transmitter model error).
    pub lag_psd: T,
    /// Pressure measurement noise, mca (1 σ).
    pub pressure_sigma_mca: T,
    /// Flow measurement noise, l/s (1 σ).
    pub flow_sigma_lps: T,
    /// VFD speed reading noise, rpm (1 σ).
    pub speed_sigma_rpm: T,
    /// Initial standard deviations: speed rpm, k2, head scale, torque scale, p_f mca, q_f l/s.
    pub initial_sigma: [T; STATES],
    /// Innovation gate, in standard deviations of the innovation (> 0).
    pub gate_sigma: T,
    /// Rejections in a row after which a channel's innovation is taken as real (≥ 1).
    pub max_rejections: u8,
    /// Standard deviation added to k2 when a rejected change is taken as real.
    pub k2_jump_sigma: T,
    /// Range of k2 (min, max), > 0.
    pub k2_range: (T, T),
    /// Range of both curve scales (min, max), > 0.
    pub scale_range: (T, T),
    /// A measurement channel missing (or implausible) for longer than this, s, is lost: the
    /// curve scales it made observable are held until it returns (> 0; longer than the
    /// slowest channel's period, the flow's 100 ms).
    pub lost_after_s: T,
}

impl<T: Real> ObserverConfig<T> {
    /// Defaults for the paper's bench and this project's transmitters (pressure lag 20 ms,
    /// flow lag 40 ms, the noise of a 12-bit 4-20 mA reading), tuned on synthetic records
    /// whose valve steps ±30 % and whose curves are off by a few percent (see the tests).
    pub fn paper() -> Self {
        let f = T::from_f64;
        Self {
            params: BenchParams::paper(),
            pressure_lag_s: f(0.020),
            flow_lag_s: f(0.120),
            pressure_lag_sd_s: f(PAPER_PRESSURE_LAG_SD_S),
            flow_lag_sd_s: f(0.100),
            drive_lag_s: f(0.025),
            drive_lag_sd_s: f(0.025),
            water_inertia: f(0.05),
            water_inertia_sd: f(0.075),
            speed_psd: f(400.0),
            k2_psd: f(1e-6),
            head_scale_psd: f(1e-7),
            torque_scale_psd: f(1e-7),
            lag_psd: f(1e-6),
            pressure_sigma_mca: f(0.006),
            flow_sigma_lps: f(0.04),
            speed_sigma_rpm: f(2.0),
            initial_sigma: [f(100.0), f(0.02), f(0.1), f(0.1), f(0.2), f(2.0)],
            gate_sigma: f(6.0),
            max_rejections: 5,
            k2_jump_sigma: f(0.02),
            k2_range: (f(0.02), f(1.0)),
            scale_range: (f(0.5), f(1.5)),
            lost_after_s: f(1.0),
        }
    }

    /// `Ok` if usable: valid model parameters, finite non-negative lags and noise densities,
    /// positive measurement noises, initial sigmas and gate, ordered positive ranges that hold
    /// the paper's values.
    pub fn validate(&self) -> Result<(), ObserverError> {
        self.params.validate().map_err(ObserverError::Model)?;
        let nonneg = |x: T| x.is_finite() && x >= T::ZERO;
        let pos = |x: T| x.is_finite() && x > T::ZERO;
        let ok = nonneg(self.pressure_lag_s)
            && nonneg(self.flow_lag_s)
            && nonneg(self.pressure_lag_sd_s)
            && nonneg(self.flow_lag_sd_s)
            && nonneg(self.drive_lag_s)
            && nonneg(self.drive_lag_sd_s)
            && nonneg(self.water_inertia)
            && nonneg(self.water_inertia_sd)
            && nonneg(self.speed_psd)
            && nonneg(self.k2_psd)
            && nonneg(self.head_scale_psd)
            && nonneg(self.torque_scale_psd)
            && nonneg(self.lag_psd)
            && pos(self.pressure_sigma_mca)
            && pos(self.flow_sigma_lps)
            && pos(self.speed_sigma_rpm)
            && self.initial_sigma.iter().all(|&s| pos(s))
            && pos(self.gate_sigma)
            && self.max_rejections >= 1
            && nonneg(self.k2_jump_sigma)
            && pos(self.k2_range.0)
            && self.k2_range.1.is_finite()
            && self.k2_range.0 < self.k2_range.1
            && pos(self.scale_range.0)
            && self.scale_range.1.is_finite()
            && self.scale_range.0 < T::ONE
            && T::ONE < self.scale_range.1
            && pos(self.lost_after_s)
            && self.k2_range.0 <= self.params.valve_k2
            && self.params.valve_k2 <= self.k2_range.1;
        if ok {
            Ok(())
        } else {
            Err(ObserverError::Config)
        }
    }
}

/// Why an observer could not be built or stepped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ObserverError {
    /// The model's parameters are not valid.
    Model(BenchError),
    /// A configuration value is out of range (see [`ObserverConfig::validate`]).
    Config,
    /// `dt` is not finite or not in (0, [`MAX_DT_S`](super::MAX_DT_S)] s.
    Step,
}

impl core::fmt::Display for ObserverError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ObserverError::Model(e) => write!(f, "observer model: {e}"),
            ObserverError::Config => f.write_str("observer configuration out of range"),
            // A literal, not `{MAX_DT_S}`: float formatting would cost the MCU ≈ 10 KB.
            ObserverError::Step => f.write_str("observer step must be in (0, 10] s"),
        }
    }
}
