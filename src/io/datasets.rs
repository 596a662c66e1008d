//! Where the public datasets live on a user's machine (EuRoC, imu_tk's
//! samples, pose graphs; `docs/datasets.md` names them and where to download
//! them): the folder named by the environment variable `TUMBLE_DATA`, laid out
//! as that page says. Examples and benchmarks that need a dataset take it from
//! there and print `SKIPPED` without it.

use std::path::PathBuf;

/// The environment variable naming the datasets' folder.
pub const DATA_VAR: &str = "TUMBLE_DATA";

/// `$TUMBLE_DATA/rel` when the variable is set and that path exists, else
/// `None` after printing a `SKIPPED` line that says what was looked for.
pub fn dataset(rel: &str) -> Option<PathBuf> {
    let Some(root) = std::env::var_os(DATA_VAR) else {
        println!("SKIPPED: {DATA_VAR} is not set (the folder of the datasets in docs/datasets.md; {rel} is needed)");
        return None;
    };
    let path = PathBuf::from(root).join(rel);
    if path.exists() {
        Some(path)
    } else {
        println!("SKIPPED: {} is absent", path.display());
        None
    }
}
