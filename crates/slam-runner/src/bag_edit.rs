//! Bags made from other bags, for the figures and tests of docs/datasets.md: raw images re-encoded
//! as PNG in `sensor_msgs/msg/CompressedImage` (on `<topic>/compressed`, the raw topic left out), and
//! a bag played several times in a row with its stamps moved on (a longer bag of the same frames). The
//! input is read a record at a time (the `mcap` crate's streaming reader), never whole.

use std::{collections::BTreeMap, io::Read, path::Path};

use mcap::{
    records::{MessageHeader, Record},
    sans_io::{LinearReadEvent, LinearReader},
};
use slam_dataset::ros::msgs::{
    read_header, write_compressed_image, ImagePayload, CAMERA_INFO, COMPRESSED_IMAGE, IMAGE,
};
use slam_frontend::image_io::{decode_raw_image, encode_png};

use crate::error::{Result, RunnerError};

/// What to change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BagEdit {
    /// Re-encode raw images as PNG compressed images.
    pub png: bool,
    /// Play the input this many times in a row (1: once).
    pub repeat: usize,
}

/// A message of the input: its topic, schema (name, encoding, text), log time and bytes.
struct Message {
    topic: String,
    schema: (String, String, Vec<u8>),
    encoding: String,
    log_time: u64,
    data: Vec<u8>,
}

/// Every message of `input` (one MCAP file), in file order, streamed to `each`.
fn for_each_message(input: &Path, each: &mut dyn FnMut(Message) -> Result<()>) -> Result<()> {
    let err = |e: String| RunnerError::Invalid(format!("{}: {e}", input.display()));
    let mut file = std::fs::File::open(input).map_err(|e| err(e.to_string()))?;
    let mut reader = LinearReader::new();
    let mut schemas: BTreeMap<u16, (String, String, Vec<u8>)> = BTreeMap::new();
    let mut channels: BTreeMap<u16, (String, u16, String)> = BTreeMap::new();
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| err(e.to_string()))? {
            LinearReadEvent::ReadRequest(n) => {
                let got = file.read(reader.insert(n)).map_err(|e| err(e.to_string()))?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { opcode, data } => {
                match mcap::parse_record(opcode, data).map_err(|e| err(e.to_string()))? {
                    Record::Schema { header, data } => {
                        schemas.insert(header.id, (header.name, header.encoding, data.into_owned()));
                    }
                    Record::Channel(c) => {
                        channels.insert(c.id, (c.topic, c.schema_id, c.message_encoding));
                    }
                    Record::Message { header, data } => {
                        let (topic, schema, encoding) = channels
                            .get(&header.channel_id)
                            .cloned()
                            .ok_or_else(|| err("a message before its channel".into()))?;
                        let schema = schemas.get(&schema).cloned().unwrap_or_default();
                        each(Message { topic, schema, encoding, log_time: header.log_time, data: data.into_owned() })?;
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(())
}

/// `sensor_msgs/msg/CompressedImage`'s definition.
const COMPRESSED_DEFINITION: &str = "std_msgs/Header header\nstring format\nuint8[] data\n\
    ================================================================================\nMSG: std_msgs/Header\n\
    builtin_interfaces/Time stamp\nstring frame_id\n\
    ================================================================================\nMSG: builtin_interfaces/Time\n\
    int32 sec\nuint32 nanosec\n";

/// A message whose header stamp is moved on by `shift_ns` (the messages read here start with one).
fn shifted(data: &[u8], shift_ns: i64) -> Option<Vec<u8>> {
    let h = read_header(data).ok()?;
    let t = h.stamp_ns + shift_ns;
    let mut out = data.to_vec();
    out.get_mut(4..8)?.copy_from_slice(&(t.div_euclid(1_000_000_000) as i32).to_le_bytes());
    out.get_mut(8..12)?.copy_from_slice(&(t.rem_euclid(1_000_000_000) as u32).to_le_bytes());
    Some(out)
}

/// Write `output` from `input` with `edit` (atomically); returns the messages written.
pub fn edit_bag(input: &Path, output: &Path, edit: BagEdit) -> Result<usize> {
    let err = |e: String| RunnerError::Invalid(format!("{}: {e}", output.display()));
    // the input's span: each repetition starts a frame period after the previous one ends
    let (mut first, mut last, mut count) = (u64::MAX, 0u64, 0usize);
    for_each_message(input, &mut |m| {
        (first, last, count) = (first.min(m.log_time), last.max(m.log_time), count + 1);
        Ok(())
    })?;
    let span = last.saturating_sub(first);
    let step = span + span / count.max(2) as u64;
    let file = slam_core::files::AtomicWrite::create(output)?;
    let f = std::fs::OpenOptions::new().write(true).open(file.temporary()).map_err(|e| err(e.to_string()))?;
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .compression_threads(0)
        .create(std::io::BufWriter::new(f))
        .map_err(|e| err(e.to_string()))?;
    let mut ids: BTreeMap<String, u16> = BTreeMap::new();
    let mut sequence: BTreeMap<u16, u32> = BTreeMap::new();
    let mut written = 0;
    for k in 0..edit.repeat.max(1) {
        let shift = k as u64 * step;
        for_each_message(input, &mut |m| {
            let decoded = m.encoding == "cdr" && [IMAGE, COMPRESSED_IMAGE, CAMERA_INFO].contains(&m.schema.0.as_str());
            let mut data =
                if decoded && shift > 0 { shifted(&m.data, shift as i64).unwrap_or(m.data.clone()) } else { m.data };
            let (mut topic, mut schema) = (m.topic, m.schema);
            if edit.png && schema.0 == IMAGE {
                let (h, payload) = ImagePayload::read(IMAGE, &data).map_err(|e| err(e.to_string()))?;
                let ImagePayload::Raw { width, height, encoding, big_endian, step, data: px } = payload else {
                    return Err(err(format!("{topic}: an {IMAGE} message that is not a raw image")));
                };
                let colour = encoding != "mono8" && encoding != "mono16";
                let image = decode_raw_image(&topic, (width, height), &encoding, big_endian, step, &px, colour)?;
                data = write_compressed_image(&h, "png", &encode_png(&image)?);
                topic = format!("{topic}/compressed");
                schema =
                    (COMPRESSED_IMAGE.to_string(), "ros2msg".to_string(), COMPRESSED_DEFINITION.as_bytes().to_vec());
            }
            let id = match ids.get(&topic) {
                Some(id) => *id,
                None => {
                    let s = w.add_schema(&schema.0, &schema.1, &schema.2).map_err(|e| err(e.to_string()))?;
                    let id = w.add_channel(s, &topic, &m.encoding, &BTreeMap::new()).map_err(|e| err(e.to_string()))?;
                    ids.insert(topic.clone(), id);
                    id
                }
            };
            let seq = sequence.entry(id).or_default();
            let header = MessageHeader {
                channel_id: id,
                sequence: *seq,
                log_time: m.log_time + shift,
                publish_time: m.log_time + shift,
            };
            *seq += 1;
            w.write_to_known_channel(&header, &data).map_err(|e| err(e.to_string()))?;
            written += 1;
            Ok(())
        })?;
    }
    w.finish().map_err(|e| err(e.to_string()))?;
    drop(w);
    file.commit()?;
    Ok(written)
}
