#![no_main]
//! Every target in one binary, picked by the `AMC_FUZZ_TARGET` environment
//! variable: one file to copy to a bigger machine and run the targets side by
//! side there (`fuzz/run.sh --all-in-one`).

use std::sync::OnceLock;

fn target() -> fn(&[u8]) {
    static TARGET: OnceLock<fn(&[u8])> = OnceLock::new();
    *TARGET.get_or_init(|| {
        let name = std::env::var("AMC_FUZZ_TARGET").unwrap_or_default();
        amc_fuzz::TARGETS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, f)| *f)
            .unwrap_or_else(|| {
                let names: Vec<_> = amc_fuzz::TARGETS.iter().map(|(n, _)| *n).collect();
                eprintln!("set AMC_FUZZ_TARGET to one of: {}", names.join(", "));
                std::process::exit(2)
            })
    })
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| target()(data));
