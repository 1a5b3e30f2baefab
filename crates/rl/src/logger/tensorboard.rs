//! TensorBoard event files: scalars written in the format TensorBoard reads.
//!
//! Written by hand because the format is small and stable (TFRecord framing around `Event`
//! protocol buffers) and the Rust crates for it are unmaintained or pull in a protobuf compiler.
//!
//! A file is a sequence of records: `u64 length (LE)`, `u32 masked CRC32C(length)`, `data`,
//! `u32 masked CRC32C(data)`. Each `data` is an `Event` message:
//! `wall_time: double = 1`, `step: int64 = 2`, `file_version: string = 3`, `summary: Summary = 5`;
//! `Summary { repeated Value value = 1 }`, `Value { string tag = 1; float simple_value = 2 }`.

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

fn masked_crc(data: &[u8]) -> u32 {
    let crc = crc32c::crc32c(data);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn put_key(out: &mut Vec<u8>, field: u32, wire: u8) {
    put_varint(out, ((field as u64) << 3) | wire as u64);
}

fn put_bytes(out: &mut Vec<u8>, field: u32, bytes: &[u8]) {
    put_key(out, field, 2);
    put_varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

fn encode_event(wall_time: f64, step: i64, body: EventBody<'_>) -> Vec<u8> {
    let mut out = Vec::with_capacity(64);
    put_key(&mut out, 1, 1);
    out.extend_from_slice(&wall_time.to_le_bytes());
    put_key(&mut out, 2, 0);
    put_varint(&mut out, step as u64);
    match body {
        EventBody::FileVersion(v) => put_bytes(&mut out, 3, v.as_bytes()),
        EventBody::Scalars(values) => {
            let mut summary = Vec::new();
            for (tag, value) in values {
                let mut v = Vec::new();
                put_bytes(&mut v, 1, tag.as_bytes());
                put_key(&mut v, 2, 5);
                v.extend_from_slice(&value.to_le_bytes());
                put_bytes(&mut summary, 1, &v);
            }
            put_bytes(&mut out, 5, &summary);
        }
    }
    out
}

enum EventBody<'a> {
    FileVersion(&'a str),
    Scalars(&'a [(&'a str, f32)]),
}

/// Writes scalar summaries to `events.out.tfevents.<time>.<host>` in a log directory.
pub struct TensorBoardWriter {
    file: BufWriter<File>,
    path: PathBuf,
}

fn now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

impl TensorBoardWriter {
    /// Creates a new event file in `dir` (created if needed).
    pub fn create(dir: &Path) -> io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "fairgrasp".into());
        let stamp = now();
        let mut name = format!("events.out.tfevents.{}.{host}", stamp as u64);
        // Two writers created in the same second (e.g. a resumed run) must not share a file.
        let mut n = 1;
        while dir.join(&name).exists() {
            name = format!("events.out.tfevents.{}.{host}.{n}", stamp as u64);
            n += 1;
        }
        let path = dir.join(name);
        let mut writer = Self {
            file: BufWriter::new(File::create(&path)?),
            path,
        };
        writer.write_record(&encode_event(
            stamp,
            0,
            EventBody::FileVersion("brain.Event:2"),
        ))?;
        writer.flush()?;
        Ok(writer)
    }

    /// The event file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write_record(&mut self, data: &[u8]) -> io::Result<()> {
        let len = (data.len() as u64).to_le_bytes();
        self.file.write_all(&len)?;
        self.file.write_all(&masked_crc(&len).to_le_bytes())?;
        self.file.write_all(data)?;
        self.file.write_all(&masked_crc(data).to_le_bytes())
    }

    /// Writes scalars (tag, value) at a global step.
    pub fn add_scalars<S: AsRef<str>>(&mut self, step: u64, values: &[(S, f32)]) -> io::Result<()> {
        if values.is_empty() {
            return Ok(());
        }
        let values: Vec<(&str, f32)> = values.iter().map(|(k, v)| (k.as_ref(), *v)).collect();
        let event = encode_event(now(), step as i64, EventBody::Scalars(&values));
        self.write_record(&event)
    }

    /// Pushes buffered records to the file.
    pub fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

impl Drop for TensorBoardWriter {
    fn drop(&mut self) {
        let _ = self.file.flush();
    }
}

/// One scalar read back from an event file.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalarEvent {
    /// The global step it was logged at (environment steps, in this crate's runs).
    pub step: i64,
    /// When it was written, in seconds since the Unix epoch.
    pub wall_time: f64,
    /// Its tag (`rollout/ep_rew_mean`, …).
    pub tag: String,
    /// The value.
    pub value: f32,
}

fn read_varint(data: &[u8], pos: &mut usize) -> Option<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *data.get(*pos)?;
        *pos += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b < 0x80 {
            return Some(v);
        }
    }
    None
}

/// Iterates (field, wire type, payload) of a protobuf message, skipping unknown wire types.
fn fields(data: &[u8]) -> Option<Vec<(u32, u8, &[u8])>> {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < data.len() {
        let key = read_varint(data, &mut pos)?;
        let (field, wire) = ((key >> 3) as u32, (key & 7) as u8);
        let start = pos;
        match wire {
            0 => {
                read_varint(data, &mut pos)?;
            }
            1 => pos += 8,
            2 => {
                let len = read_varint(data, &mut pos)? as usize;
                let start = pos;
                pos = pos.checked_add(len)?;
                out.push((field, wire, data.get(start..pos)?));
                continue;
            }
            5 => pos += 4,
            _ => return None,
        }
        out.push((field, wire, data.get(start..pos)?));
    }
    Some(out)
}

/// Reads every scalar of an event file, checking the record framing and checksums. Used by
/// tests and by tools that plot learning curves.
pub fn read_scalars(path: &Path) -> io::Result<Vec<ScalarEvent>> {
    let bad = |what: &str| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{}: {what}", path.display()),
        )
    };
    let mut bytes = Vec::new();
    File::open(path)?.read_to_end(&mut bytes)?;
    let mut pos = 0;
    let mut out = Vec::new();
    while pos < bytes.len() {
        let header = bytes
            .get(pos..pos + 12)
            .ok_or_else(|| bad("truncated record header"))?;
        let len = u64::from_le_bytes(header[..8].try_into().expect("8 bytes")) as usize;
        if masked_crc(&header[..8]) != u32::from_le_bytes(header[8..12].try_into().expect("4")) {
            return Err(bad("length checksum mismatch"));
        }
        let data = bytes
            .get(pos + 12..pos + 12 + len)
            .ok_or_else(|| bad("truncated record"))?;
        let crc = bytes
            .get(pos + 12 + len..pos + 16 + len)
            .ok_or_else(|| bad("truncated checksum"))?;
        if masked_crc(data) != u32::from_le_bytes(crc.try_into().expect("4")) {
            return Err(bad("data checksum mismatch"));
        }
        pos += 16 + len;
        let mut wall_time = 0.0;
        let mut step = 0;
        let mut summary = None;
        for (field, _, payload) in fields(data).ok_or_else(|| bad("malformed event"))? {
            match field {
                1 => {
                    wall_time =
                        f64::from_le_bytes(payload.try_into().map_err(|_| bad("wall_time"))?)
                }
                2 => {
                    let mut p = 0;
                    step = read_varint(payload, &mut p).ok_or_else(|| bad("step"))? as i64;
                }
                5 => summary = Some(payload),
                _ => {}
            }
        }
        let Some(summary) = summary else { continue };
        for (field, _, value) in fields(summary).ok_or_else(|| bad("malformed summary"))? {
            if field != 1 {
                continue;
            }
            let mut tag = String::new();
            let mut simple = None;
            for (f, _, payload) in fields(value).ok_or_else(|| bad("malformed value"))? {
                match f {
                    1 => tag = String::from_utf8_lossy(payload).into_owned(),
                    2 => {
                        simple = Some(f32::from_le_bytes(
                            payload.try_into().map_err(|_| bad("simple_value"))?,
                        ))
                    }
                    _ => {}
                }
            }
            if let Some(value) = simple {
                out.push(ScalarEvent {
                    step,
                    wall_time,
                    tag,
                    value,
                });
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masked_crc_matches_tensorflow_reference_values() {
        // CRC32C("123456789") = 0xE3069283 (the standard check value); masking rotates and adds.
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
        assert_eq!(
            masked_crc(b"123456789"),
            0xE306_9283u32.rotate_right(15).wrapping_add(0xa282_ead8)
        );
    }

    #[test]
    fn scalars_round_trip_through_an_event_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = TensorBoardWriter::create(dir.path()).unwrap();
        w.add_scalars(10, &[("rollout/ep_rew_mean", 1.5), ("train/loss", -0.25)])
            .unwrap();
        w.add_scalars(20, &[("rollout/ep_rew_mean", 2.5)]).unwrap();
        w.flush().unwrap();
        let events = read_scalars(w.path()).unwrap();
        let got: Vec<(i64, &str, f32)> = events
            .iter()
            .map(|e| (e.step, e.tag.as_str(), e.value))
            .collect();
        assert_eq!(
            got,
            vec![
                (10, "rollout/ep_rew_mean", 1.5),
                (10, "train/loss", -0.25),
                (20, "rollout/ep_rew_mean", 2.5)
            ]
        );
        // A flipped byte is caught by the checksum.
        let mut bytes = std::fs::read(w.path()).unwrap();
        let last = bytes.len() - 6;
        bytes[last] ^= 0xff;
        std::fs::write(w.path(), &bytes).unwrap();
        assert!(read_scalars(w.path()).is_err());
    }
}
