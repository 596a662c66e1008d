//! `tumble apply`: write a corrected recording in the layout it was read from.

use crate::io::imu_write::{write_asl_imu, write_imu_columns, write_imu_tk_pair};
use crate::io::{ImuRecording, RecordingOptions};
use std::path::{Path, PathBuf};

/// Write `rec` (already corrected) into `out` in the layout of `input`: an
/// ASL folder gets `out/mav0/imu0/data.csv`; imu_tk's pair keeps its two file
/// names; a text file keeps its name, column order and time unit. ROS bags
/// and MCAP files are refused (write an ASL folder from them with `tumble sim`-style tools instead).
pub fn write_like_input(
    rec: &ImuRecording,
    input: &Path,
    opts: &RecordingOptions,
    out: &Path,
) -> Result<Vec<PathBuf>, String> {
    let name = |p: &Path| -> Result<PathBuf, String> {
        let f = p.file_name().ok_or_else(|| format!("{}: not a file", p.display()))?;
        Ok(out.join(f))
    };
    let err = |e: crate::InputError| e.to_string();
    if input.is_dir() {
        let p = out.join("mav0").join("imu0").join("data.csv");
        write_asl_imu(&p, rec).map_err(err)?;
        return Ok(vec![p]);
    }
    let ext = input.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if matches!(ext.as_deref(), Some("bag") | Some("mcap")) {
        return Err(format!(
            "{}: apply cannot write ROS bags or MCAP files; convert to an ASL folder or CSV first",
            input.display()
        ));
    }
    if let Some(g) = &opts.gyro_file {
        let (a, g) = (name(input)?, name(g)?);
        write_imu_tk_pair(&a, &g, rec, opts.format.time_unit).map_err(err)?;
        return Ok(vec![a, g]);
    }
    let mut p = name(input)?;
    if ext.as_deref() == Some("gz") {
        p.set_extension("");
    }
    write_imu_columns(&p, rec, &opts.format.columns, opts.format.time_unit).map_err(err)?;
    Ok(vec![p])
}
