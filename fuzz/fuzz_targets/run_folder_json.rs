//! The run-folder JSON files (`config.json`, `normalization.json`, `train_state.json`) on
//! hostile text: each must parse and pass the shared checks, or fail with an error, never
//! panic. The first byte picks the file; a config and statistics that both parse are checked
//! together as `zoo_rtn::checkpoint::read_meta` checks them (with the valid counterpart).
#![no_main]

use libfuzzer_sys::fuzz_target;
use zoo_nn::train_loop::TrainState;
use zoo_rtn::Config;
use zoo_rtn::checkpoint::check_meta;
use zoo_rtn::features::FeatureStats;

fuzz_target!(|data: &[u8]| {
    let Some((&which, text)) = data.split_first() else { return };
    let config = Config::tiny();
    let stats = FeatureStats::identity(config.joints);
    match which % 3 {
        0 => {
            if let Ok(c) = serde_json::from_slice::<Config>(text) {
                let s = FeatureStats::identity(c.joints.min(1 << 16));
                let _ = check_meta(&c, &s);
                let _ = check_meta(&c, &stats);
            }
        }
        1 => {
            if let Ok(s) = serde_json::from_slice::<FeatureStats>(text) {
                let _ = check_meta(&config, &s);
            }
        }
        _ => {
            if let Ok(s) = serde_json::from_slice::<TrainState>(text) {
                let _ = serde_json::to_string(&s);
            }
        }
    }
});
