//! Protection that acts: the alarms of [`model_core::monitor`] that trip the controller to
//! 0 % torque, and the rules that let it run again.
//!
//! | alarm | action by default | delay | latched | acknowledge |
//! |---|---|---|---|---|
//! | overspeed (bit 8) | **trip**: 0 % | at the alarm: the first speed over the limit, checked every 1 ms (the drive's reading, else the observer's) | yes | SCADA writes mode 0; clears once the speed has been 100 rpm below the limit for 1 s |
//! | dry run (bit 3) | **trip**: 0 % | at the alarm (2 s of dry readings) | yes | mode 0; clears once the rule has read wet (or the pump below 500 rpm, where it cannot judge) for 2 s |
//! | no flow / closed valve (bit 4) | warning; a trip if configured | the trip once the alarm has stood [`ProtectionConfig::no_flow_trip_s`] (30 s) | the trip, yes | mode 0; the trip clears once the alarm has |
//! | transmitters, VFD link, end of curve, load changed, model residual | warning (the VFD link alarm already applies 0 % while it stands) | | as the alarm | |
//!
//! What trips is [`ProtectionConfig::trip_on`] (SCADA holding register 6): bit 0 dry run,
//! bit 1 overspeed, bit 2 no flow; 1 trips, 0 warns.
//!
//! A trip holds the torque reference at 0 % in every mode and remembers its causes (the
//! alarm bits, input register 23). It is acknowledged by a SCADA write of mode 0 (stop), the
//! same write that acknowledges the latched alarms, and clears once its causes have gone (the
//! alarms have cleared): at once if they had, else as soon as they have (an acknowledge given
//! while a cause stands is kept until the cause has gone; a new cause needs a new one). The
//! controller then stays at 0 % until it sees mode 0: restarting takes a mode written after
//! the trip cleared, never the mode the register held before (no automatic restart into a dry
//! pump). A pump that the trip has stopped can no longer show a dry run (the rule does not
//! judge below 500 rpm): a dry-run trip can be acknowledged at rest, and a pump still dry
//! trips again within seconds of the restart.

use model_core::monitor::{DRY_RUN, NO_FLOW, OVERSPEED};

/// Holding register 6, bit 0: dry run trips.
pub const TRIP_DRY_RUN: u16 = 1 << 0;
/// Holding register 6, bit 1: overspeed trips.
pub const TRIP_OVERSPEED: u16 = 1 << 1;
/// Holding register 6, bit 2: no flow trips (after its delay).
pub const TRIP_NO_FLOW: u16 = 1 << 2;
/// Every bit of holding register 6.
pub const TRIP_ALL: u16 = TRIP_DRY_RUN | TRIP_OVERSPEED | TRIP_NO_FLOW;
/// Overspeed limit's range, rpm (holding register 5).
pub const OVERSPEED_RANGE_RPM: core::ops::RangeInclusive<u16> = 100..=4000;
/// No-flow trip delay's range, s (holding register 7).
pub const NO_FLOW_TRIP_RANGE_S: core::ops::RangeInclusive<u16> = 1..=3600;

/// What trips, and when (SCADA holding registers 5..=7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProtectionConfig {
    /// Overspeed limit, rpm ([`OVERSPEED_RANGE_RPM`]): 1 925, 110 % of the nominal 1 750.
    pub overspeed_rpm: u16,
    /// Alarms that trip ([`TRIP_DRY_RUN`], [`TRIP_OVERSPEED`], [`TRIP_NO_FLOW`]; 0..=7):
    /// dry run and overspeed.
    pub trip_on: u16,
    /// How long the no-flow alarm stands before it trips (if [`TRIP_NO_FLOW`]), s
    /// ([`NO_FLOW_TRIP_RANGE_S`]): 30.
    pub no_flow_trip_s: u16,
}

impl ProtectionConfig {
    /// The safe defaults (see the fields).
    pub const DEFAULT: Self = Self {
        overspeed_rpm: 1925,
        trip_on: TRIP_DRY_RUN | TRIP_OVERSPEED,
        no_flow_trip_s: 30,
    };

    /// `true` if every field is in its range.
    pub fn is_valid(&self) -> bool {
        OVERSPEED_RANGE_RPM.contains(&self.overspeed_rpm)
            && self.trip_on & !TRIP_ALL == 0
            && NO_FLOW_TRIP_RANGE_S.contains(&self.no_flow_trip_s)
    }
}

impl Default for ProtectionConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The trip state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Protection {
    /// Alarm bits that tripped (0: not tripped).
    tripped: u16,
    /// An acknowledge waits for the causes to go.
    ack: bool,
    /// After a trip cleared: 0 % until mode 0 is seen.
    hold_until_stop: bool,
    /// How long the no-flow alarm has stood, s.
    no_flow_s: f32,
}

impl Protection {
    /// Not tripped.
    pub const fn new() -> Self {
        Self {
            tripped: 0,
            ack: false,
            hold_until_stop: false,
            no_flow_s: 0.0,
        }
    }

    /// The alarm bits that tripped ([`model_core::monitor`]'s bits); 0 when not tripped.
    pub fn causes(&self) -> u16 {
        self.tripped
    }

    /// Tripped.
    pub fn tripped(&self) -> bool {
        self.tripped != 0
    }

    /// One control step of `dt_s` seconds: `alarms` are the monitor's bits now, `stopped`
    /// that the mode is 0 (stop), `acknowledge` that SCADA wrote mode 0 since the last step.
    /// Returns `true` if the torque must be 0 % (tripped, or not yet restarted).
    pub fn update(
        &mut self,
        config: &ProtectionConfig,
        dt_s: f32,
        alarms: u16,
        stopped: bool,
        acknowledge: bool,
    ) -> bool {
        if alarms & (DRY_RUN | OVERSPEED | NO_FLOW) == 0
            && self.tripped == 0
            && self.no_flow_s == 0.0
        {
            // Nothing that could trip, nothing tripped (so no acknowledge pending): the
            // common step, in a few instructions.
            if stopped {
                self.hold_until_stop = false;
            }
            return self.hold_until_stop;
        }
        let mut trips = 0;
        if config.trip_on & TRIP_DRY_RUN != 0 {
            trips |= alarms & DRY_RUN;
        }
        if config.trip_on & TRIP_OVERSPEED != 0 {
            trips |= alarms & OVERSPEED;
        }
        self.no_flow_s = if alarms & NO_FLOW != 0 {
            self.no_flow_s + dt_s
        } else {
            0.0
        };
        if config.trip_on & TRIP_NO_FLOW != 0 && self.no_flow_s >= f32::from(config.no_flow_trip_s)
        {
            trips |= NO_FLOW;
        }
        if trips & !self.tripped != 0 {
            // A new cause: an acknowledge given before it does not cover it.
            self.tripped |= trips;
            self.ack = false;
        }
        if acknowledge && self.tripped != 0 {
            self.ack = true;
        }
        if self.ack && self.tripped & alarms == 0 {
            self.tripped = 0;
            self.ack = false;
            self.hold_until_stop = true;
        }
        if stopped {
            self.hold_until_stop = false;
        }
        self.tripped != 0 || self.hold_until_stop
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model_core::monitor::{LOAD_CHANGED, PRESSURE_TRANSMITTER};

    const C: ProtectionConfig = ProtectionConfig::DEFAULT;

    #[test]
    fn defaults_are_valid_and_out_of_range_values_are_not() {
        assert!(C.is_valid());
        for bad in [
            ProtectionConfig {
                overspeed_rpm: 99,
                ..C
            },
            ProtectionConfig {
                overspeed_rpm: 4001,
                ..C
            },
            ProtectionConfig { trip_on: 8, ..C },
            ProtectionConfig {
                no_flow_trip_s: 0,
                ..C
            },
        ] {
            assert!(!bad.is_valid(), "{bad:?}");
        }
    }

    #[test]
    fn a_trip_holds_until_acknowledged_with_its_cause_gone_then_needs_a_stop() {
        let mut p = Protection::new();
        assert!(!p.update(&C, 1e-3, LOAD_CHANGED | PRESSURE_TRANSMITTER, false, false));
        assert!(p.update(&C, 1e-3, DRY_RUN, false, false), "dry run trips");
        assert_eq!(p.causes(), DRY_RUN);
        assert!(
            p.update(&C, 1e-3, 0, false, false),
            "latched: the alarm gone, no ack"
        );
        // Acknowledged while the alarm stands: still tripped; the acknowledge waits.
        assert!(p.update(&C, 1e-3, DRY_RUN, true, true));
        assert!(p.update(&C, 1e-3, DRY_RUN, true, false));
        // The mode written back to manual meanwhile: the trip clears with the alarm, but
        // the controller holds 0 % until it sees a stop.
        assert!(p.update(&C, 1e-3, 0, false, false), "no automatic restart");
        assert!(!p.tripped());
        assert!(p.update(&C, 1e-3, 0, false, false));
        assert!(!p.update(&C, 1e-3, 0, true, false), "stop seen");
        assert!(!p.update(&C, 1e-3, 0, false, false), "a new mode runs");
    }

    #[test]
    fn a_new_cause_needs_a_new_acknowledge() {
        let mut p = Protection::new();
        p.update(&C, 1e-3, OVERSPEED, false, false);
        p.update(&C, 1e-3, OVERSPEED, true, true);
        p.update(&C, 1e-3, OVERSPEED | DRY_RUN, true, false);
        assert_eq!(p.causes(), OVERSPEED | DRY_RUN);
        assert!(
            p.update(&C, 1e-3, 0, true, false),
            "the acknowledge was spent"
        );
        assert!(!p.update(&C, 1e-3, 0, true, true));
    }

    #[test]
    fn warnings_do_not_trip_and_no_flow_trips_after_its_delay_if_configured() {
        let mut p = Protection::new();
        let warn = ProtectionConfig { trip_on: 0, ..C };
        for _ in 0..100_000 {
            assert!(!p.update(&warn, 1e-3, DRY_RUN | OVERSPEED | NO_FLOW, false, false));
        }
        let mut p = Protection::new();
        for _ in 0..100_000 {
            assert!(
                !p.update(&C, 1e-3, NO_FLOW, false, false),
                "a warning by default"
            );
        }
        let trip = ProtectionConfig {
            trip_on: TRIP_NO_FLOW,
            no_flow_trip_s: 5,
            ..C
        };
        let mut p = Protection::new();
        let mut t = 0;
        while !p.update(&trip, 1e-3, NO_FLOW, false, false) {
            t += 1;
            assert!(t < 6000);
        }
        assert!((4990..=5000).contains(&t), "after {t} ms");
        assert_eq!(p.causes(), NO_FLOW);
        // The alarm going before the delay restarts it.
        let mut p = Protection::new();
        for _ in 0..4000 {
            p.update(&trip, 1e-3, NO_FLOW, false, false);
        }
        p.update(&trip, 1e-3, 0, false, false);
        for _ in 0..4000 {
            assert!(!p.update(&trip, 1e-3, NO_FLOW, false, false));
        }
    }
}
