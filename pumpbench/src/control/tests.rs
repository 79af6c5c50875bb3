//! Unit tests of `control`: the figures on known responses, the scenarios.

use super::*;
