//! ROS 2 bags in MCAP, ROS 2's default storage: one `.mcap` file, or a rosbag2 folder whose
//! `metadata.yaml` lists its `.mcap` files. [`Bag::open`] reads the bag once from start to end, a
//! record at a time (never the whole file), and keeps a small index: every topic with its type and
//! message count, each image message's header stamp and place in the file, each camera's first
//! `CameraInfo`. A [`BagReader`] then reads single image messages from those places, decompressing a
//! chunk once for all the messages it holds (the last two chunks are kept, so a run reading its frames
//! in order decompresses each chunk once and holds at most two in memory, whatever the bag's length).
//!
//! MCAP's records are parsed and its chunks decompressed (zstd, lz4) and checked (CRC) by the `mcap`
//! crate; this module walks the top-level records itself, so that it knows each record's offset (for
//! the index and for errors) and tells a file cut short (a record running past the end: a recording
//! that stopped without closing its file, e.g. at a power loss; the messages before the cut are used,
//! with a warning) from a damaged one (a chunk whose contents do not decompress or fail their CRC:
//! an error naming the file and the chunk's offset).

use std::{
    borrow::Cow,
    collections::{BTreeMap, BTreeSet},
    fs::File,
    io::{BufReader, Read, Seek, SeekFrom},
    path::{Path, PathBuf},
};

use mcap::records::{op, Record};

use super::msgs::{CameraInfo, ImageInfo, ImagePayload, CAMERA_INFO, COMPRESSED_IMAGE, IMAGE};
use crate::DatasetError;

/// The bytes every MCAP file starts (and ends) with.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// The largest record read into memory: 1 GiB. MCAP writers close a chunk after a few MB (rosbag2's
/// default is 4 MiB; a chunk grows past that only by its last message), and the largest image a frame
/// may hold is 192 MiB (`slam_core::files::IMAGE`); a larger length is a damaged file, not data.
const RECORD_LIMIT: u64 = 1 << 30;

/// Where a message lies: the file of the bag, the top-level record holding it (a chunk, or the message
/// itself), and its place among the chunk's records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MessageRef {
    /// Index of the file in [`Bag::files`].
    pub file: u32,
    /// Byte offset of the top-level record in that file.
    pub record: u64,
    /// The message's place among its chunk's records (0 for a message outside chunks).
    pub inner: u32,
}

/// One image message of the index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexedImage {
    /// Header stamp, nanoseconds since the epoch.
    pub stamp_ns: i64,
    /// Where it is.
    pub at: MessageRef,
    /// `(width, height)` of a raw image (a compressed image's size is in its file).
    pub size: Option<(u32, u32)>,
}

/// A topic of the bag, as `inspect` lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct Topic {
    /// Name.
    pub name: String,
    /// Message type (the schema's name, e.g. `sensor_msgs/msg/Image`).
    pub schema: String,
    /// Message encoding (`cdr` for ROS 2).
    pub encoding: String,
    /// Messages.
    pub count: usize,
    /// First and last time, nanoseconds: header stamps for images and camera infos, the bag's log
    /// times for the rest.
    pub span_ns: Option<(i64, i64)>,
    /// Pixel encodings (raw images) or formats (compressed ones) seen, each once.
    pub layouts: BTreeSet<String>,
    /// Messages that could not be read as their type (counted, skipped; the first named in the
    /// bag's warnings).
    pub unreadable: usize,
}

impl Topic {
    /// Messages a second over the topic's span (`None` for fewer than two messages or no span).
    pub fn rate_hz(&self) -> Option<f64> {
        let (a, b) = self.span_ns?;
        (self.count > 1 && b > a).then(|| (self.count - 1) as f64 / ((b - a) as f64 * 1e-9))
    }

    /// Whether its messages are images this reader decodes.
    pub fn is_image(&self) -> bool {
        self.encoding == "cdr" && (self.schema == IMAGE || self.schema == COMPRESSED_IMAGE)
    }
}

/// A ROS 2 bag read once and indexed ([`Bag::open`]).
#[derive(Debug, Clone)]
pub struct Bag {
    /// What was opened: an `.mcap` file or a rosbag2 folder.
    pub path: PathBuf,
    /// Its MCAP files, in order.
    pub files: Vec<PathBuf>,
    /// Every topic, by name.
    pub topics: Vec<Topic>,
    /// Image messages of each image topic, in stamp order.
    pub images: BTreeMap<String, Vec<IndexedImage>>,
    /// The first `CameraInfo` of each camera-info topic.
    pub camera_infos: BTreeMap<String, CameraInfo>,
    /// What was odd about the bag and how it was handled, one sentence each (a file cut short, messages
    /// that could not be read).
    pub warnings: Vec<String>,
}

/// A channel of one file: its topic, schema name and message encoding.
#[derive(Debug, Clone)]
struct Channel {
    topic: String,
    schema: String,
    encoding: String,
}

/// What one file's records told so far.
struct Scan<'b> {
    file: u32,
    path: &'b Path,
    schemas: BTreeMap<u16, String>,
    channels: BTreeMap<u16, Channel>,
    topics: &'b mut BTreeMap<String, Topic>,
    images: &'b mut BTreeMap<String, Vec<IndexedImage>>,
    infos: &'b mut BTreeMap<String, CameraInfo>,
    /// The first unreadable message of each topic: (offset, reason).
    bad: &'b mut BTreeMap<String, (u64, String)>,
}

fn invalid(path: &Path, message: String) -> DatasetError {
    DatasetError::Invalid { path: path.to_path_buf(), message }
}

fn io(path: &Path, source: std::io::Error) -> DatasetError {
    DatasetError::Io { path: path.to_path_buf(), source }
}

/// The `.mcap` files of a bag: the file itself, or the files a rosbag2 folder's `metadata.yaml` lists
/// (else every `.mcap` file in the folder, sorted by name).
pub fn bag_files(path: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    if !path.is_dir() {
        slam_core::files::regular_file(path)?;
        return Ok(vec![path.to_path_buf()]);
    }
    let meta = path.join("metadata.yaml");
    let mut files = Vec::new();
    if meta.exists() {
        let text = crate::read_text(&meta, &slam_core::files::SMALL)?;
        let docs = yaml_rust2::YamlLoader::load_from_str(&text).map_err(|e| DatasetError::Parse {
            path: meta.clone(),
            line: e.marker().line(),
            message: e.info().to_string(),
        })?;
        let info = &docs.first().map(|d| &d["rosbag2_bagfile_information"]);
        if let Some(info) = info.filter(|i| !i.is_badvalue()) {
            if let Some(storage) = info["storage_identifier"].as_str() {
                if storage != "mcap" {
                    return Err(invalid(
                        &meta,
                        format!("storage_identifier is '{storage}': only MCAP bags are read (convert with `ros2 bag convert`)"),
                    ));
                }
            }
            for f in info["relative_file_paths"].as_vec().into_iter().flatten() {
                let name =
                    f.as_str().ok_or_else(|| invalid(&meta, "relative_file_paths holds a non-text entry".into()))?;
                files.push(path.join(name));
            }
        }
    }
    if files.is_empty() {
        let entries = std::fs::read_dir(path).map_err(|e| io(path, e))?;
        files = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
            .collect();
        files.sort();
    }
    if files.is_empty() {
        return Err(invalid(
            path,
            "a ROS 2 bag folder needs .mcap files (listed in its metadata.yaml or beside it)".into(),
        ));
    }
    for f in &files {
        slam_core::files::regular_file(f)?;
    }
    Ok(files)
}

/// Whether a path is a bag: an `.mcap` file, or a folder with a `metadata.yaml` or `.mcap` files.
pub fn is_bag(path: &Path) -> bool {
    if path.is_dir() {
        path.join("metadata.yaml").is_file()
            || std::fs::read_dir(path)
                .is_ok_and(|mut d| d.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x == "mcap"))))
    } else {
        path.extension().is_some_and(|x| x == "mcap")
    }
}

/// A top-level record: its offset, opcode and body.
struct RawRecord {
    offset: u64,
    opcode: u8,
    body: Vec<u8>,
}

/// Reads a file's top-level records in order.
struct Records<R> {
    r: R,
    pos: u64,
    size: u64,
    /// The file ends with MCAP's closing magic: it was closed, so a record running past its end is
    /// damaged, not cut short.
    whole: bool,
}

/// How reading a record ended when it did not give one.
enum Stop {
    /// The file ends at a record boundary or inside a record: cut short at this offset.
    Cut(u64, String),
    Error(DatasetError),
}

impl<R: Read> Records<R> {
    fn next(&mut self, path: &Path) -> Result<RawRecord, Stop> {
        let offset = self.pos;
        let mut head = [0u8; 9];
        let got = read_full(&mut self.r, &mut head).map_err(|e| Stop::Error(io(path, e)))?;
        if got == 0 {
            return Err(Stop::Cut(
                offset,
                "the file ends after a whole record, before the summary and closing magic".into(),
            ));
        }
        if got < head.len() {
            return Err(Stop::Cut(
                offset,
                format!("the file ends inside a record's header at byte {}", offset + got as u64),
            ));
        }
        let opcode = head[0];
        let len = u64::from_le_bytes(head[1..].try_into().unwrap_or_default());
        let body_at = offset + 9;
        if len > self.size.saturating_sub(body_at) && self.whole {
            return Err(Stop::Error(invalid(
                path,
                format!("the record at byte {offset} declares {len} bytes, past the end of a file that was closed whole (it ends with MCAP's closing magic): the record is damaged"),
            )));
        }
        if len > self.size.saturating_sub(body_at) {
            return Err(Stop::Cut(
                offset,
                format!(
                    "the record at byte {offset} declares {len} bytes, {} are left in the file",
                    self.size - body_at.min(self.size)
                ),
            ));
        }
        if len > RECORD_LIMIT {
            return Err(Stop::Error(invalid(
                path,
                format!("the record at byte {offset} declares {len} bytes, more than the 1 GiB a record may hold here (MCAP writers close chunks after a few MB)"),
            )));
        }
        let mut body = vec![0u8; len as usize];
        let got = read_full(&mut self.r, &mut body).map_err(|e| Stop::Error(io(path, e)))?;
        if got < body.len() {
            return Err(Stop::Cut(offset, format!("the file ends inside the record at byte {offset}")));
        }
        self.pos = body_at + len;
        Ok(RawRecord { offset, opcode, body })
    }
}

/// Read until `buf` is full or the input ends; the bytes read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

fn open_records(path: &Path) -> Result<Records<BufReader<File>>, DatasetError> {
    let mut file = File::open(path).map_err(|e| io(path, e))?;
    let size = file.metadata().map_err(|e| io(path, e))?.len();
    let mut tail = [0u8; 8];
    let whole = size >= 16
        && file.seek(SeekFrom::Start(size - 8)).is_ok()
        && read_full(&mut file, &mut tail).is_ok_and(|n| n == 8)
        && &tail == MAGIC;
    file.seek(SeekFrom::Start(0)).map_err(|e| io(path, e))?;
    let mut r = BufReader::with_capacity(1 << 20, file);
    let mut magic = [0u8; 8];
    let got = read_full(&mut r, &mut magic).map_err(|e| io(path, e))?;
    if got < 8 || &magic != MAGIC {
        return Err(invalid(path, "not an MCAP file: it does not start with MCAP's magic bytes".into()));
    }
    Ok(Records { r, pos: 8, size, whole })
}

impl Scan<'_> {
    fn schema(&mut self, header: mcap::records::SchemaHeader) {
        self.schemas.insert(header.id, header.name);
    }

    fn channel(&mut self, c: mcap::records::Channel) {
        // schema 0: a channel without a schema (its messages are not decoded)
        let schema = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
        let topic = self.topics.entry(c.topic.clone()).or_insert_with(|| Topic {
            name: c.topic.clone(),
            schema: schema.clone(),
            encoding: c.message_encoding.clone(),
            count: 0,
            span_ns: None,
            layouts: BTreeSet::new(),
            unreadable: 0,
        });
        if topic.schema.is_empty() {
            topic.schema = schema.clone();
        }
        self.channels.insert(c.id, Channel { topic: c.topic, schema, encoding: c.message_encoding });
    }

    fn message(&mut self, header: &mcap::records::MessageHeader, data: &[u8], at: MessageRef) -> Result<(), String> {
        let Some(ch) = self.channels.get(&header.channel_id) else {
            return Err(format!(
                "a message at byte {} names channel {} before any record defines it",
                at.record, header.channel_id
            ));
        };
        let Some(topic) = self.topics.get_mut(&ch.topic) else { return Ok(()) };
        topic.count += 1;
        let decoded = ch.encoding == "cdr" && [IMAGE, COMPRESSED_IMAGE, CAMERA_INFO].contains(&ch.schema.as_str());
        let stamp = if !decoded {
            i64::try_from(header.log_time).ok()
        } else if ch.schema == CAMERA_INFO {
            match CameraInfo::read(data) {
                Ok(info) => {
                    let s = info.header.stamp_ns;
                    self.infos.entry(ch.topic.clone()).or_insert(info);
                    Some(s)
                }
                Err(e) => {
                    topic.unreadable += 1;
                    self.bad.entry(ch.topic.clone()).or_insert((at.record, e.to_string()));
                    None
                }
            }
        } else {
            match ImageInfo::read(&ch.schema, data) {
                Ok(info) => {
                    let layout = match &info.raw {
                        Some((_, _, enc)) => enc.clone(),
                        None => info.format.clone(),
                    };
                    if !topic.layouts.contains(&layout) {
                        topic.layouts.insert(layout);
                    }
                    let size = info.raw.as_ref().map(|(w, h, _)| (*w, *h));
                    self.images.entry(ch.topic.clone()).or_default().push(IndexedImage {
                        stamp_ns: info.header.stamp_ns,
                        at,
                        size,
                    });
                    Some(info.header.stamp_ns)
                }
                Err(e) => {
                    topic.unreadable += 1;
                    self.bad.entry(ch.topic.clone()).or_insert((at.record, e.to_string()));
                    None
                }
            }
        };
        if let Some(s) = stamp {
            topic.span_ns = Some(topic.span_ns.map_or((s, s), |(a, b)| (a.min(s), b.max(s))));
        }
        Ok(())
    }

    /// The records inside a chunk, in order; an error names the chunk's offset.
    fn chunk(&mut self, rec: &RawRecord) -> Result<(), DatasetError> {
        let damaged = |what: String| {
            invalid(
                self.path,
                format!("the chunk at byte {} is damaged ({what}); a bag whose data is damaged in the middle is not used (copy the messages that are intact with `mcap recover`)", rec.offset),
            )
        };
        let (header, data) = match mcap::parse_record(op::CHUNK, &rec.body) {
            Ok(Record::Chunk { header, data }) => (header, data),
            Ok(_) => return Err(damaged("not a chunk".into())),
            Err(e) => return Err(damaged(e.to_string())),
        };
        if header.uncompressed_size > RECORD_LIMIT {
            return Err(damaged(format!(
                "{} bytes uncompressed, more than the 1 GiB a chunk may hold here",
                header.uncompressed_size
            )));
        }
        let reader = mcap::read::ChunkReader::new(header, &data).map_err(|e| damaged(e.to_string()))?;
        for (inner, r) in reader.enumerate() {
            let at = MessageRef { file: self.file, record: rec.offset, inner: inner as u32 };
            match r.map_err(|e| damaged(e.to_string()))? {
                Record::Schema { header, .. } => self.schema(header),
                Record::Channel(c) => self.channel(c),
                Record::Message { header, data } => self.message(&header, &data, at).map_err(damaged)?,
                _ => {}
            }
        }
        Ok(())
    }
}

impl Scan<'_> {
    /// Read this scan's file up to the end of its data (or to a cut, said in `warnings`).
    fn file_records(&mut self, warnings: &mut Vec<String>) -> Result<(), DatasetError> {
        let file = self.path;
        let mut records = open_records(file)?;
        loop {
            let rec = match records.next(file) {
                Ok(r) => r,
                Err(Stop::Cut(at, why)) => {
                    let kept: usize = self.images.values().map(Vec::len).sum();
                    warnings.push(format!(
                        "{} is cut short at byte {at} ({why}), as a recording that stopped without closing its file (a power loss, a killed recorder): the {kept} image messages before the cut are used",
                        file.display()
                    ));
                    break;
                }
                Err(Stop::Error(e)) => return Err(e),
            };
            if !self.record(&rec)? {
                break;
            }
        }
        Ok(())
    }

    /// Take in one top-level record of the file; false when the data ends there.
    fn record(&mut self, rec: &RawRecord) -> Result<bool, DatasetError> {
        let file = self.path;
        let bad_record =
            |e: mcap::McapError| invalid(file, format!("the record at byte {} cannot be read: {e}", rec.offset));
        match rec.opcode {
            op::CHUNK => self.chunk(rec)?,
            op::SCHEMA => {
                if let Record::Schema { header, .. } = mcap::parse_record(op::SCHEMA, &rec.body).map_err(bad_record)? {
                    self.schema(header)
                }
            }
            op::CHANNEL => {
                if let Record::Channel(c) = mcap::parse_record(op::CHANNEL, &rec.body).map_err(bad_record)? {
                    self.channel(c)
                }
            }
            op::MESSAGE => {
                if let Record::Message { header, data } =
                    mcap::parse_record(op::MESSAGE, &rec.body).map_err(bad_record)?
                {
                    let at = MessageRef { file: self.file, record: rec.offset, inner: 0 };
                    self.message(&header, &data, at).map_err(|m| invalid(file, m))?
                }
            }
            // the data ends here: the summary after it repeats what was read
            op::DATA_END | op::FOOTER => return Ok(false),
            _ => {}
        }
        Ok(true)
    }
}

/// One warning per topic with messages that cannot be read as their type: how many, and the first.
fn unreadable_warnings(
    topics: &BTreeMap<String, Topic>,
    bad: &BTreeMap<String, (u64, String)>,
    warnings: &mut Vec<String>,
) {
    for (topic, (at, why)) in bad {
        let n = topics.get(topic).map_or(0, |t: &Topic| t.unreadable);
        warnings.push(format!(
            "{n} message(s) of {topic} cannot be read as their type and are skipped (first: the record at byte {at}: {why})"
        ));
    }
}

impl Bag {
    /// Read and index a bag (an `.mcap` file or a rosbag2 folder).
    pub fn open(path: &Path) -> Result<Bag, DatasetError> {
        let files = bag_files(path)?;
        let mut topics = BTreeMap::new();
        let mut images = BTreeMap::new();
        let mut infos = BTreeMap::new();
        let mut bad = BTreeMap::new();
        let mut warnings = Vec::new();
        for (k, file) in files.iter().enumerate() {
            let mut scan = Scan {
                file: k as u32,
                path: file,
                schemas: BTreeMap::new(),
                channels: BTreeMap::new(),
                topics: &mut topics,
                images: &mut images,
                infos: &mut infos,
                bad: &mut bad,
            };
            scan.file_records(&mut warnings)?;
        }
        for list in images.values_mut() {
            // stable: messages of one stamp keep the bag's order
            list.sort_by_key(|m: &IndexedImage| m.stamp_ns);
        }
        unreadable_warnings(&topics, &bad, &mut warnings);
        Ok(Bag {
            path: path.to_path_buf(),
            files,
            topics: topics.into_values().collect(),
            images,
            camera_infos: infos,
            warnings,
        })
    }

    /// A topic by name.
    pub fn topic(&self, name: &str) -> Option<&Topic> {
        self.topics.iter().find(|t| t.name == name)
    }
}

/// A decompressed chunk: its messages' channel topics and bytes by place (other records `None`).
type ChunkMessages = Vec<Option<(u16, Vec<u8>)>>;

/// Reads image messages of an indexed bag by their place ([`MessageRef`]).
pub struct BagReader {
    files: Vec<PathBuf>,
    open: BTreeMap<u32, File>,
    /// The last chunks read, newest last: (file, offset) and its messages.
    chunks: Vec<((u32, u64), ChunkMessages)>,
}

/// Chunks kept decompressed: a frame's two images may lie in two chunks.
const KEPT_CHUNKS: usize = 2;

impl BagReader {
    /// A reader of `bag`'s files (opened when first needed).
    pub fn new(bag: &Bag) -> Self {
        Self { files: bag.files.clone(), open: BTreeMap::new(), chunks: Vec::new() }
    }

    fn record(&mut self, file: u32, offset: u64) -> Result<(PathBuf, RawRecord), DatasetError> {
        let path = self.files.get(file as usize).cloned().unwrap_or_default();
        let f = match self.open.entry(file) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => e.insert(File::open(&path).map_err(|s| io(&path, s))?),
        };
        let size = f.metadata().map_err(|e| io(&path, e))?.len();
        f.seek(SeekFrom::Start(offset)).map_err(|e| io(&path, e))?;
        let mut records = Records { r: BufReader::with_capacity(64 << 10, &*f), pos: offset, size, whole: false };
        match records.next(&path) {
            Ok(r) => Ok((path, r)),
            Err(Stop::Error(e)) => Err(e),
            Err(Stop::Cut(_, why)) => {
                Err(invalid(&path, format!("the record at byte {offset} is no longer whole: {why}")))
            }
        }
    }

    /// The bytes of the message at `at`.
    pub fn message(&mut self, at: MessageRef) -> Result<Vec<u8>, DatasetError> {
        let key = (at.file, at.record);
        if let Some(k) = self.chunks.iter().position(|(c, _)| *c == key) {
            return self.in_chunk(k, at);
        }
        let (path, rec) = self.record(at.file, at.record)?;
        let bad = |e: String| invalid(&path, format!("the record at byte {}: {e}", at.record));
        match rec.opcode {
            op::MESSAGE => match mcap::parse_record(op::MESSAGE, &rec.body).map_err(|e| bad(e.to_string()))? {
                Record::Message { data, .. } => Ok(data.into_owned()),
                _ => Err(bad("not a message".into())),
            },
            op::CHUNK => {
                let (header, data) = match mcap::parse_record(op::CHUNK, &rec.body).map_err(|e| bad(e.to_string()))? {
                    Record::Chunk { header, data } => (header, data),
                    _ => return Err(bad("not a chunk".into())),
                };
                let mut messages = ChunkMessages::new();
                for r in mcap::read::ChunkReader::new(header, &data).map_err(|e| bad(e.to_string()))? {
                    messages.push(match r.map_err(|e| bad(e.to_string()))? {
                        Record::Message { header, data } => Some((header.channel_id, owned(data))),
                        _ => None,
                    });
                }
                if self.chunks.len() == KEPT_CHUNKS {
                    self.chunks.remove(0);
                }
                self.chunks.push((key, messages));
                self.in_chunk(self.chunks.len() - 1, at)
            }
            other => Err(bad(format!("opcode {other:#04x} holds no message"))),
        }
    }

    fn in_chunk(&self, k: usize, at: MessageRef) -> Result<Vec<u8>, DatasetError> {
        let path = self.files.get(at.file as usize).cloned().unwrap_or_default();
        self.chunks[k].1.get(at.inner as usize).and_then(|m| m.as_ref()).map(|(_, d)| d.clone()).ok_or_else(|| {
            invalid(&path, format!("the chunk at byte {} has no message at place {}", at.record, at.inner))
        })
    }

    /// The image message at `at`, of schema `schema`.
    pub fn image(&mut self, schema: &str, at: MessageRef) -> Result<ImagePayload, DatasetError> {
        let data = self.message(at)?;
        let path = self.files.get(at.file as usize).cloned().unwrap_or_default();
        ImagePayload::read(schema, &data)
            .map(|(_, p)| p)
            .map_err(|e| invalid(&path, format!("the message in the record at byte {}: {e}", at.record)))
    }
}

fn owned(data: Cow<'_, [u8]>) -> Vec<u8> {
    data.into_owned()
}
