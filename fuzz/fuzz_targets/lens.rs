#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| amc_fuzz::lens(data));
