//! The one seeded random generator of the zoo, re-exported from the motion core so that
//! models, data generation and the runtime draw from the same type.

pub use zoo_motion::rng::SplitMix64;
