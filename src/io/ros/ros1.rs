//! ROS 1 bag headers, checked before the `rosbag` crate reads the file (it
//! slices the file at the header's `index_pos` without checking it).

use crate::error::InputError;
use std::path::Path;

/// Check a ROS 1 bag's header before handing it to `rosbag`, which slices the
/// file at the header's `index_pos` without checking it.
/// `data` is the start of the file (at least its header record), `file_len` its length.
pub(super) fn check_bag_header(path: &Path, data: &[u8], file_len: usize) -> Result<(), InputError> {
    let bad = |m: &str| Err(InputError::file(path, format!("not a ROS 1 bag: {m}")));
    let magic = b"#ROSBAG V2.0\n";
    if !data.starts_with(magic) {
        return bad("missing the '#ROSBAG V2.0' line");
    }
    let mut pos = magic.len();
    let u32_at = |p: usize| data.get(p..p + 4).map(|b| u32::from_le_bytes(b.try_into().unwrap_or([0; 4])) as usize);
    let Some(hlen) = u32_at(pos) else { return bad("truncated header") };
    pos += 4;
    let end = pos.saturating_add(hlen);
    if end > data.len() {
        return bad("truncated header");
    }
    // The header record's data (padding to 4 KiB) follows its fields: the index
    // starts after it, with at least a record's two length fields.
    let Some(data_len) = u32_at(end) else { return bad("truncated header record") };
    let record_end = end.saturating_add(4).saturating_add(data_len);
    let mut index_pos = None;
    while pos + 4 <= end {
        let Some(flen) = u32_at(pos) else { return bad("truncated header field") };
        let field = data.get(pos + 4..pos.saturating_add(4).saturating_add(flen)).unwrap_or(&[]);
        if let Some(v) = field.strip_prefix(b"index_pos=") {
            index_pos = Some(v.get(..8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8]))));
        }
        pos = pos.saturating_add(4).saturating_add(flen);
    }
    match index_pos {
        None => bad("its header has no index_pos field"),
        Some(None) => bad("its header's index_pos field is shorter than 8 bytes"),
        // An index at the very end is empty (no connections); anything else needs room for a record.
        Some(Some(i))
            if (i as usize) < record_end || (i as usize != file_len && (i as usize).saturating_add(8) > file_len) =>
        {
            bad(&format!(
                "its header's index_pos ({i}) does not point past the header record ({record_end} bytes) to a record \
             inside the file ({file_len} bytes) (truncated while recording? try `rosbag reindex`)"
            ))
        }
        Some(Some(_)) => Ok(()),
    }
}
