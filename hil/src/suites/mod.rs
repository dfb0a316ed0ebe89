//! Suites of runs with a verdict per row: the fault matrix ([`faults`]), the turntable's
//! validation ([`validate`]), fuzzing nav's inputs ([`fuzz`]) and the benchmarks ([`mod@bench`]).

pub mod bench;
pub mod faults;
pub mod fuzz;
pub mod validate;
