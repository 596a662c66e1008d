//! The numeric-table reader under every IMU, trajectory and tracks format:
//! any bytes give a table or an error, never a panic; a few specs are tried.
#![no_main]
use libfuzzer_sys::fuzz_target;
use std::path::Path;
use tumble::io::table::{parse_table_from, TableSpec};
use tumble::io::TimeUnit;

fuzz_target!(|data: &[u8]| {
    let specs = [
        TableSpec { time: Some((0, TimeUnit::Ns)), triads: vec![[1, 2, 3], [4, 5, 6]], triad_names: vec!["g".into(), "a".into()], ..Default::default() },
        TableSpec { time: Some((0, TimeUnit::S)), values: vec![1, 2, 3], names: vec!["x".into(), "y".into(), "z".into()], ..Default::default() },
        TableSpec { time: None, values: vec![2], names: vec!["v".into()], ..Default::default() },
    ];
    for spec in &specs {
        if let Ok(t) = parse_table_from(Path::new("fuzz.csv"), data, spec) {
            assert!(!t.t_ns.is_empty());
            for c in &t.columns {
                assert_eq!(c.len(), t.t_ns.len());
                assert!(c.iter().all(|v| v.is_finite()));
            }
            for c in &t.triads {
                assert_eq!(c.len(), t.t_ns.len());
            }
            let _ = t.lines.line(t.t_ns.len() - 1);
        }
    }
});
