//! The four ways ROS recordings are stored, behind one message iterator:
//! ROS 1 bags (`.bag`, crate `rosbag`), MCAP files (`.mcap`, crate `mcap`,
//! memory-mapped and streamed chunk by chunk), rosbag2 SQLite files (`.db3`,
//! crate `rusqlite` with its bundled SQLite, rows streamed) and rosbag2
//! folders (`metadata.yaml` naming `.db3` or `.mcap` files, read in order).

use super::msgs::Encoding;
use crate::error::InputError;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What kind of ROS storage a path is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Storage {
    /// A ROS 1 bag file.
    Ros1(PathBuf),
    /// One MCAP file.
    Mcap(PathBuf),
    /// One rosbag2 SQLite file.
    Db3(PathBuf),
    /// A rosbag2 folder: its storage files in recording order.
    Folder(Vec<Storage>),
}

/// One topic: name, type (normalized to `pkg/Type`) and its number of
/// messages when the file's index says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub name: String,
    /// Message type, `pkg/Type` (ROS 2's `pkg/msg/Type` without `msg/`).
    pub msg_type: String,
    /// Messages on it, when known without reading them.
    pub count: Option<u64>,
}

/// One stored message, borrowed for the duration of a callback.
pub struct RawMessage<'a> {
    /// Topic name.
    pub topic: &'a str,
    /// Message type, `pkg/Type`.
    pub msg_type: &'a str,
    /// Wire format of `data`.
    pub encoding: Encoding,
    /// The serialized message.
    pub data: &'a [u8],
    /// When the recorder received it \[ns\] (not the message's own stamp).
    pub log_time_ns: i64,
}

/// `sensor_msgs/msg/Imu` → `sensor_msgs/Imu` (ROS 1 names are kept).
pub fn normalize_type(t: &str) -> String {
    match t.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, "msg", name] => format!("{pkg}/{name}"),
        _ => t.to_string(),
    }
}

impl Storage {
    /// Recognise a ROS recording by its path: a folder with `metadata.yaml`
    /// (rosbag2) — or without it but holding `.db3`/`.mcap` files (a recording
    /// cut short before rosbag2 wrote it), read in name order —, or a `.bag`,
    /// `.mcap` or `.db3` file. `Ok(None)` for anything else.
    pub fn of(path: &Path) -> Result<Option<Storage>, InputError> {
        if path.is_dir() {
            let meta = path.join("metadata.yaml");
            if meta.is_file() {
                return folder(path, &meta).map(Some);
            }
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| InputError::file(path, format!("cannot list: {e}")))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && matches!(p.extension().and_then(|e| e.to_str()), Some("db3" | "mcap")))
                .collect();
            files.sort();
            return Ok((!files.is_empty()).then(|| {
                Storage::Folder(
                    files
                        .into_iter()
                        .map(
                            |p| {
                                if p.extension().is_some_and(|e| e == "db3") {
                                    Storage::Db3(p)
                                } else {
                                    Storage::Mcap(p)
                                }
                            },
                        )
                        .collect(),
                )
            }));
        }
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        Ok(match ext.as_deref() {
            Some("bag") => Some(Storage::Ros1(path.to_path_buf())),
            Some("mcap") => Some(Storage::Mcap(path.to_path_buf())),
            Some("db3") => Some(Storage::Db3(path.to_path_buf())),
            Some("zstd") if path.to_string_lossy().ends_with(".db3.zstd") => {
                return Err(InputError::file(path, "is a zstd-compressed rosbag2 file")
                    .with_hint("decompress it first: `ros2 bag decompress` (or `zstd -d FILE`)"))
            }
            _ => None,
        })
    }

    /// The path to name in messages.
    pub fn path(&self) -> &Path {
        match self {
            Storage::Ros1(p) | Storage::Mcap(p) | Storage::Db3(p) => p,
            Storage::Folder(files) => files.first().map(|f| f.path()).unwrap_or(Path::new("")),
        }
    }

    /// The topics stored, with types and message counts (from the files'
    /// indexes where they have one; a `.db3` is scanned once to count).
    pub fn topics(&self) -> Result<Vec<TopicInfo>, InputError> {
        self.list(true)
    }

    /// The topics stored and their types, without counting a `.db3`'s messages
    /// (what choosing topics needs).
    pub fn topic_types(&self) -> Result<Vec<TopicInfo>, InputError> {
        self.list(false)
    }

    fn list(&self, counts: bool) -> Result<Vec<TopicInfo>, InputError> {
        let mut all: BTreeMap<String, TopicInfo> = BTreeMap::new();
        let mut add = |t: TopicInfo| {
            let e = all.entry(t.name.clone()).or_insert(TopicInfo { count: Some(0), ..t.clone() });
            e.count = e.count.zip(t.count).map(|(a, b)| a + b);
        };
        match self {
            Storage::Ros1(p) => ros1_topics(p)?.into_iter().for_each(&mut add),
            Storage::Mcap(p) => mcap_guarded(p, || mcap_topics(p))?.into_iter().for_each(&mut add),
            Storage::Db3(p) => db3_topics(p, counts)?.into_iter().for_each(&mut add),
            Storage::Folder(files) => {
                for f in files {
                    f.list(counts)?.into_iter().for_each(&mut add);
                }
            }
        }
        Ok(all.into_values().collect())
    }

    /// Call `f` on every message whose topic is in `topics`, in storage order
    /// (recording order for rosbag2 files, chunk order for bags and MCAP; not
    /// necessarily by stamp: callers sort).
    pub fn for_each(
        &self,
        topics: &[&str],
        f: &mut dyn FnMut(&RawMessage) -> Result<(), InputError>,
    ) -> Result<(), InputError> {
        match self {
            Storage::Ros1(p) => ros1_each(p, topics, f),
            Storage::Mcap(p) => mcap_guarded(p, || mcap_each(p, topics, f)),
            Storage::Db3(p) => db3_each(p, topics, f),
            Storage::Folder(files) => files.iter().try_for_each(|s| s.for_each(topics, f)),
        }
    }
}

/// The part of rosbag2's `metadata.yaml` tumble needs.
#[derive(serde::Deserialize)]
struct Metadata {
    rosbag2_bagfile_information: BagInfo,
}

#[derive(serde::Deserialize)]
struct BagInfo {
    storage_identifier: String,
    relative_file_paths: Vec<String>,
    #[serde(default)]
    compression_mode: String,
}

fn folder(dir: &Path, meta: &Path) -> Result<Storage, InputError> {
    let m: Metadata = crate::io::yaml::read_yaml(meta)?;
    let info = m.rosbag2_bagfile_information;
    if !info.compression_mode.is_empty() && info.compression_mode != "NONE" {
        return Err(InputError::file(meta, format!("the bag is compressed ({})", info.compression_mode))
            .with_hint("decompress it first: `ros2 bag decompress`"));
    }
    let mut files = Vec::new();
    for rel in &info.relative_file_paths {
        // Older rosbag2 versions list paths with the folder's name in front.
        let direct = dir.join(rel);
        let p = if direct.exists() { direct } else { dir.join(Path::new(rel).file_name().unwrap_or_default()) };
        if !p.is_file() {
            return Err(InputError::file(meta, format!("lists '{rel}', which is not in {}", dir.display())));
        }
        files.push(match info.storage_identifier.as_str() {
            "sqlite3" => Storage::Db3(p),
            "mcap" => Storage::Mcap(p),
            other => {
                return Err(InputError::file(meta, format!("storage '{other}' is not read (sqlite3 and mcap are)")))
            }
        });
    }
    if files.is_empty() {
        return Err(InputError::file(meta, "lists no storage files (relative_file_paths is empty)"));
    }
    Ok(Storage::Folder(files))
}

// --- ROS 1 -----------------------------------------------------------------

fn ros1_open(path: &Path) -> Result<rosbag::RosBag, InputError> {
    // The header record comes first (4 KiB in bags rosbag writes); read only that much.
    let io = |e: std::io::Error| InputError::file(path, format!("cannot read: {e}"));
    let file = std::fs::File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len() as usize;
    let mut head = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(file, 1 << 20), &mut head).map_err(io)?;
    super::ros1::check_bag_header(path, &head, file_len)?;
    rosbag::RosBag::new(path).map_err(|e| InputError::file(path, format!("not a readable ROS 1 bag: {e}")))
}

fn ros1_bad(path: &Path) -> impl Fn(rosbag::Error) -> InputError + '_ {
    move |e| InputError::file(path, format!("corrupt bag record: {e}"))
}

fn ros1_topics(path: &Path) -> Result<Vec<TopicInfo>, InputError> {
    let bag = ros1_open(path)?;
    let mut conns: BTreeMap<String, String> = BTreeMap::new();
    for rec in bag.index_records() {
        if let Ok(rosbag::IndexRecord::Connection(c)) = rec {
            conns.insert(c.topic.to_string(), c.tp.to_string());
        }
    }
    if conns.is_empty() {
        // A bag without its index (still being written, or never reindexed):
        // the connection records inside the chunks say the same.
        for rec in bag.chunk_records() {
            if let rosbag::ChunkRecord::Chunk(chunk) = rec.map_err(ros1_bad(path))? {
                for m in chunk.messages() {
                    if let rosbag::MessageRecord::Connection(c) = m.map_err(ros1_bad(path))? {
                        conns.insert(c.topic.to_string(), c.tp.to_string());
                    }
                }
            }
        }
    }
    Ok(conns.into_iter().map(|(name, t)| TopicInfo { name, msg_type: normalize_type(&t), count: None }).collect())
}

fn ros1_each(
    path: &Path,
    topics: &[&str],
    f: &mut dyn FnMut(&RawMessage) -> Result<(), InputError>,
) -> Result<(), InputError> {
    let bag = ros1_open(path)?;
    // Connection records come before their messages in each chunk.
    let mut conns: BTreeMap<u32, (String, String)> = BTreeMap::new();
    for rec in bag.chunk_records() {
        if let rosbag::ChunkRecord::Chunk(chunk) = rec.map_err(ros1_bad(path))? {
            for m in chunk.messages() {
                match m.map_err(ros1_bad(path))? {
                    rosbag::MessageRecord::Connection(c) if topics.contains(&c.topic) => {
                        conns.insert(c.id, (c.topic.to_string(), normalize_type(c.tp)));
                    }
                    rosbag::MessageRecord::Connection(_) => {}
                    rosbag::MessageRecord::MessageData(m) => {
                        if let Some((topic, msg_type)) = conns.get(&m.conn_id) {
                            let log_time_ns = m.time as i64;
                            f(&RawMessage { topic, msg_type, encoding: Encoding::Ros1, data: m.data, log_time_ns })?;
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

// --- MCAP ------------------------------------------------------------------

fn mcap_map(path: &Path) -> Result<memmap2::Mmap, InputError> {
    let file = std::fs::File::open(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    // SAFETY: the map is read-only and lives only while this reader uses it;
    // a file truncated meanwhile by another process would fault, as with any reader of a file being rewritten.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| InputError::file(path, format!("cannot map: {e}")))?;
    let _ = map.advise(memmap2::Advice::Sequential);
    Ok(map)
}

/// `read` on MCAP file `path`, a panic of the MCAP reader turned into an
/// error naming the file: the `mcap` crate panics on some malformed files
/// (a chunk declaring an uncompressed size beyond memory: "capacity
/// overflow", found by the `mcap` fuzz target), and bad input must never
/// crash tumble.
fn mcap_guarded<T>(path: &Path, read: impl FnOnce() -> Result<T, InputError>) -> Result<T, InputError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(read)).unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a malformed record".into());
        Err(InputError::file(path, format!("not a readable MCAP file: the MCAP reader failed ({why})")))
    })
}

fn mcap_bad(path: &Path) -> impl Fn(mcap::McapError) -> InputError + '_ {
    move |e| InputError::file(path, format!("not a readable MCAP file: {e}"))
}

fn mcap_type(c: &mcap::Channel) -> String {
    normalize_type(c.schema.as_ref().map(|s| s.name.as_str()).unwrap_or(""))
}

fn mcap_topics(path: &Path) -> Result<Vec<TopicInfo>, InputError> {
    let map = mcap_map(path)?;
    if let Ok(Some(summary)) = mcap::Summary::read(&map) {
        let counts = summary.stats.as_ref().map(|s| &s.channel_message_counts);
        return Ok(summary
            .channels
            .values()
            .map(|c| TopicInfo {
                name: c.topic.clone(),
                msg_type: mcap_type(c),
                count: counts.and_then(|m| m.get(&c.id)).copied(),
            })
            .collect());
    }
    // No summary section (a recording cut short): stream through it.
    let mut stream = mcap::read::RawMessageStream::new(&map).map_err(mcap_bad(path))?;
    let mut counts: BTreeMap<u16, u64> = BTreeMap::new();
    for m in stream.by_ref() {
        *counts.entry(m.map_err(mcap_bad(path))?.header.channel_id).or_default() += 1;
    }
    Ok(counts
        .into_iter()
        .filter_map(|(id, n)| {
            let c = stream.get_channel(id)?;
            Some(TopicInfo { name: c.topic.clone(), msg_type: mcap_type(&c), count: Some(n) })
        })
        .collect())
}

fn mcap_each(
    path: &Path,
    topics: &[&str],
    f: &mut dyn FnMut(&RawMessage) -> Result<(), InputError>,
) -> Result<(), InputError> {
    let map = mcap_map(path)?;
    let mut stream = mcap::read::RawMessageStream::new(&map).map_err(mcap_bad(path))?;
    let mut wanted: BTreeMap<u16, Option<(String, String, Encoding)>> = BTreeMap::new();
    while let Some(m) = stream.next() {
        let m = m.map_err(mcap_bad(path))?;
        let id = m.header.channel_id;
        if let std::collections::btree_map::Entry::Vacant(slot) = wanted.entry(id) {
            let c = stream.get_channel(id).ok_or_else(|| {
                InputError::file(path, format!("message {} refers to unknown channel {id}", m.header.sequence))
            })?;
            let keep = topics.contains(&c.topic.as_str());
            let enc = match c.message_encoding.as_str() {
                "cdr" => Some(Encoding::Cdr),
                "ros1" => Some(Encoding::Ros1),
                _ => None,
            };
            let entry = match (keep, enc) {
                (true, Some(e)) => Some((c.topic.clone(), mcap_type(&c), e)),
                (true, None) => {
                    return Err(InputError::file(
                        path,
                        format!("topic {} is encoded as '{}' (cdr and ros1 are read)", c.topic, c.message_encoding),
                    ))
                }
                _ => None,
            };
            slot.insert(entry);
        }
        if let Some(Some((topic, msg_type, encoding))) = wanted.get(&id) {
            let log_time_ns = m.header.log_time as i64;
            f(&RawMessage { topic, msg_type, encoding: *encoding, data: &m.data, log_time_ns })?;
        }
    }
    Ok(())
}

// --- rosbag2 SQLite ----------------------------------------------------------

fn db3_open(path: &Path) -> Result<rusqlite::Connection, InputError> {
    if !path.is_file() {
        return Err(InputError::file(path, "does not exist"));
    }
    rusqlite::Connection::open_with_flags(path, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .map_err(|e| InputError::file(path, format!("cannot open as SQLite: {e}")))
}

fn db3_bad(path: &Path) -> impl Fn(rusqlite::Error) -> InputError + '_ {
    move |e| InputError::file(path, format!("not a readable rosbag2 SQLite file: {e}"))
}

/// (id, name, type, serialization format) of every topic.
fn db3_topic_rows(path: &Path, db: &rusqlite::Connection) -> Result<Vec<(i64, String, String, String)>, InputError> {
    let mut q = db.prepare("SELECT id, name, type, serialization_format FROM topics").map_err(db3_bad(path))?;
    let rows = q.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?))).map_err(db3_bad(path))?;
    rows.collect::<Result<Vec<_>, _>>().map_err(db3_bad(path))
}

fn db3_topics(path: &Path, count: bool) -> Result<Vec<TopicInfo>, InputError> {
    let db = db3_open(path)?;
    // One pass over the table for every topic's count (no index on topic_id in rosbag2's schema).
    let counts: Option<BTreeMap<i64, i64>> = if count {
        let mut q = db.prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id").map_err(db3_bad(path))?;
        let rows = q.query_map([], |r| Ok((r.get(0)?, r.get(1)?))).map_err(db3_bad(path))?;
        Some(rows.collect::<Result<_, _>>().map_err(db3_bad(path))?)
    } else {
        None
    };
    Ok(db3_topic_rows(path, &db)?
        .into_iter()
        .map(|(id, name, t, _)| TopicInfo {
            name,
            msg_type: normalize_type(&t),
            count: counts.as_ref().map(|c| c.get(&id).copied().unwrap_or(0) as u64),
        })
        .collect())
}

fn db3_each(
    path: &Path,
    topics: &[&str],
    f: &mut dyn FnMut(&RawMessage) -> Result<(), InputError>,
) -> Result<(), InputError> {
    let db = db3_open(path)?;
    let mut wanted: BTreeMap<i64, (String, String)> = BTreeMap::new();
    for (id, name, t, format) in db3_topic_rows(path, &db)? {
        if topics.contains(&name.as_str()) {
            if format != "cdr" {
                return Err(InputError::file(path, format!("topic {name} is serialized as '{format}' (cdr is read)")));
            }
            wanted.insert(id, (name, normalize_type(&t)));
        }
    }
    if wanted.is_empty() {
        return Ok(());
    }
    let ids = wanted.keys().map(|i| i.to_string()).collect::<Vec<_>>().join(",");
    // Rowid (recording) order: a sequential scan that skips other topics' blobs. Ordering by
    // the timestamp index instead would visit every row in random order; readers sort by stamp.
    let sql = format!("SELECT topic_id, data, timestamp FROM messages WHERE topic_id IN ({ids})");
    let mut q = db.prepare(&sql).map_err(db3_bad(path))?;
    let mut rows = q.query([]).map_err(db3_bad(path))?;
    while let Some(row) = rows.next().map_err(db3_bad(path))? {
        let id: i64 = row.get(0).map_err(db3_bad(path))?;
        let data = row.get_ref(1).map_err(db3_bad(path))?.as_blob().map_err(|e| db3_bad(path)(e.into()))?;
        let log_time_ns: i64 = row.get(2).map_err(db3_bad(path))?;
        if let Some((topic, msg_type)) = wanted.get(&id) {
            f(&RawMessage { topic, msg_type, encoding: Encoding::Cdr, data, log_time_ns })?;
        }
    }
    Ok(())
}
