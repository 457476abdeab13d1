//! Tracker recordings as CSV.
//!
//! # Format
//!
//! One sample per row, nine comma-separated fields:
//!
//! ```text
//! time_us,sensor,x,y,z,qw,qx,qy,qz
//! 0,0,0.10,1.20,0.00,1,0,0,0
//! ```
//!
//! * `time_us`: unsigned integer, microseconds (any epoch). Per sensor, time
//!   must strictly increase from row to row; sensors may interleave freely.
//! * `sensor`: integer 0..=255, the tracker's sensor index.
//! * `x,y,z`: position in metres (right-handed, Y up).
//! * `qw,qx,qy,qz`: orientation quaternion `[w, x, y, z]` (DESIGN §4). Its
//!   norm must be within [`NORM_TOLERANCE`] of 1; it is stored normalised.
//!   `w ≥ 0` is not required.
//!
//! Limits, checked while reading (before more memory is taken): at most
//! [`MAX_SAMPLES`] rows, and every time stamp within [`MAX_SPAN_US`] of
//! every other (the wire's `u32` microsecond clock: 71 min 34.967 s).
//!
//! The header row is optional: if the first row's first field is not an
//! integer, the row must be exactly the header above (names compared
//! case-insensitively, surrounding spaces ignored). Blank lines and lines
//! whose first non-blank character is `#` are skipped anywhere. Fields may
//! have surrounding spaces. All numbers must be finite.
//!
//! # Orientation-only recordings (x-io IMU-Mocap)
//!
//! [`parse_xio_quaternions`] reads the x-io `Quaternion.csv` files
//! (`Timestamp (us),W,X,Y,Z`, one file per sensor) into samples with **zero
//! position**: IMUs give no position, so a rig must map such sensors to
//! orientation-only uses. [`merge_by_time`] interleaves several sensors'
//! samples into one recording, and [`write_tracker_csv`] writes the format
//! above.

use std::io::{BufRead, Write};
use std::path::Path;

use glam::{DQuat, DVec3};

use super::{ImportError, Lines};

/// How far from 1 a quaternion's norm may be before it is rejected. x-io's
/// files print 6 decimals and their norms are 1.00012.
pub const NORM_TOLERANCE: f64 = 1e-3;

/// Most samples (rows) in one recording: 2²¹, 35 minutes of one 1 kHz
/// sensor, 11.6 of three (about 150 MB in memory).
pub const MAX_SAMPLES: usize = 1 << 21;

/// The widest span of time stamps in one recording, µs: the wire's clock
/// is a `u32` of microseconds.
pub const MAX_SPAN_US: u64 = u32::MAX as u64;

/// The header row of a tracker CSV.
pub const HEADER: [&str; 9] = ["time_us", "sensor", "x", "y", "z", "qw", "qx", "qy", "qz"];

/// The header row of an x-io `Quaternion.csv`.
pub const XIO_HEADER: [&str; 5] = ["Timestamp (us)", "W", "X", "Y", "Z"];

/// One tracker reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerSample {
    /// Time stamp, microseconds.
    pub time_us: u64,
    /// Sensor index.
    pub sensor: u8,
    /// Position, metres.
    pub position: DVec3,
    /// Orientation, unit quaternion.
    pub orientation: DQuat,
}

/// Reads a tracker CSV from disk (see [`parse_tracker_csv`]).
///
/// # Errors
/// As [`parse_tracker_csv`], plus [`ImportError::Io`].
pub fn read_tracker_csv(path: &Path) -> Result<Vec<TrackerSample>, ImportError> {
    parse_tracker_csv(super::open(path)?, &path.display().to_string())
}

/// Parses a whole tracker CSV; `file` names it in errors.
///
/// # Errors
/// The first malformed row (see the module docs), with line and field.
pub fn parse_tracker_csv<R: BufRead>(
    reader: R,
    file: &str,
) -> Result<Vec<TrackerSample>, ImportError> {
    TrackerReader::new(reader, file).collect()
}

/// Streams a tracker CSV one sample at a time.
pub struct TrackerReader<R> {
    rows: Rows<R>,
    done: bool,
}

impl<R: BufRead> TrackerReader<R> {
    /// Wraps `reader`; `file` names it in errors.
    pub fn new(reader: R, file: &str) -> Self {
        Self {
            rows: Rows::new(reader, file, &HEADER, false),
            done: false,
        }
    }

    /// Allows at most `max` samples (fewer than [`MAX_SAMPLES`]).
    #[must_use]
    pub fn with_limit(mut self, max: usize) -> Self {
        self.rows.max_samples = max.min(MAX_SAMPLES);
        self
    }
}

impl<R: BufRead> Iterator for TrackerReader<R> {
    type Item = Result<TrackerSample, ImportError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.rows.next_sample(|rows, fields| {
            let sensor = rows.sensor(fields.get(1).copied())?;
            let x = rows.float(fields.get(2).copied(), "x")?;
            let y = rows.float(fields.get(3).copied(), "y")?;
            let z = rows.float(fields.get(4).copied(), "z")?;
            let q = rows.quaternion(fields.get(5..9).unwrap_or(&[]), ["qw", "qx", "qy", "qz"])?;
            Ok((sensor, DVec3::new(x, y, z), q))
        });
        match item {
            Ok(Some(sample)) => Some(Ok(sample)),
            Ok(None) => None,
            Err(e) => {
                self.done = true;
                Some(Err(e))
            }
        }
    }
}

/// Reads an x-io `Quaternion.csv` from disk (see [`parse_xio_quaternions`]).
///
/// # Errors
/// As [`parse_xio_quaternions`], plus [`ImportError::Io`].
pub fn read_xio_quaternions(path: &Path, sensor: u8) -> Result<Vec<TrackerSample>, ImportError> {
    parse_xio_quaternions(super::open(path)?, &path.display().to_string(), sensor)
}

/// Parses an x-io `Quaternion.csv` (header `Timestamp (us),W,X,Y,Z`
/// required) into samples of `sensor` with zero position.
///
/// # Errors
/// As for tracker CSVs: line and field of the first bad row.
pub fn parse_xio_quaternions<R: BufRead>(
    reader: R,
    file: &str,
    sensor: u8,
) -> Result<Vec<TrackerSample>, ImportError> {
    let mut rows = Rows::new(reader, file, &XIO_HEADER, true);
    let mut out = Vec::new();
    while let Some(sample) = rows.next_sample(|rows, fields| {
        let q = rows.quaternion(fields.get(1..5).unwrap_or(&[]), ["W", "X", "Y", "Z"])?;
        Ok((sensor, DVec3::ZERO, q))
    })? {
        out.push(sample);
    }
    Ok(out)
}

/// Interleaves several recordings by time (stable: equal times keep the
/// order of `streams`, then of each stream).
#[must_use]
pub fn merge_by_time(streams: Vec<Vec<TrackerSample>>) -> Vec<TrackerSample> {
    let mut all: Vec<TrackerSample> = streams.into_iter().flatten().collect();
    all.sort_by_key(|s| s.time_us);
    all
}

/// Writes samples as a tracker CSV with a header row; numbers are written
/// with Rust's shortest round-trip formatting, so parsing gives them back
/// exactly.
///
/// # Errors
/// Any I/O error of `out`.
pub fn write_tracker_csv<W: Write>(mut out: W, samples: &[TrackerSample]) -> std::io::Result<()> {
    writeln!(out, "{}", HEADER.join(","))?;
    for s in samples {
        let (p, q) = (s.position, s.orientation);
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{}",
            s.time_us, s.sensor, p.x, p.y, p.z, q.w, q.x, q.y, q.z
        )?;
    }
    Ok(())
}

/// Row reading shared by both CSV shapes.
struct Rows<R> {
    lines: Lines<R>,
    header: &'static [&'static str],
    header_required: bool,
    first_row: bool,
    /// Per sensor: last time and its line.
    last: Vec<Option<(u64, usize)>>,
    /// Samples read so far, and the most allowed.
    count: usize,
    max_samples: usize,
    /// Earliest and latest time stamp so far.
    span: Option<(u64, u64)>,
}

type RowFields = (u8, DVec3, DQuat);

impl<R: BufRead> Rows<R> {
    fn new(reader: R, file: &str, header: &'static [&'static str], header_required: bool) -> Self {
        Self {
            lines: Lines::new(reader, file),
            header,
            header_required,
            first_row: true,
            last: vec![None; 256],
            count: 0,
            max_samples: MAX_SAMPLES,
            span: None,
        }
    }

    /// Reads rows until a sample (parsed by `fields` after the time stamp)
    /// or the end of the file.
    fn next_sample(
        &mut self,
        parse: impl Fn(&Self, &[&str]) -> Result<RowFields, ImportError>,
    ) -> Result<Option<TrackerSample>, ImportError> {
        loop {
            if !self.lines.advance()? {
                return if self.first_row && self.header_required {
                    Err(self.lines.eof("the header row"))
                } else {
                    Ok(None)
                };
            }
            let trimmed = self.lines.text().trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let fields: Vec<String> = trimmed.split(',').map(|f| f.trim().to_owned()).collect();
            let first_row = std::mem::replace(&mut self.first_row, false);
            let looks_like_header = fields.first().is_some_and(|f| f.parse::<u64>().is_err());
            if first_row && (self.header_required || looks_like_header) {
                self.check_header(&fields)?;
                continue;
            }
            let fields: Vec<&str> = fields.iter().map(String::as_str).collect();
            if fields.len() != self.header.len() {
                let expected = format!(
                    "{} comma-separated fields ({})",
                    self.header.len(),
                    self.header.join(",")
                );
                return Err(self.lines.syntax(
                    "row",
                    &expected,
                    Some(&format!("{} fields", fields.len())),
                ));
            }
            let time_us = self.time(fields.first().copied())?;
            let (sensor, position, orientation) = parse(self, &fields)?;
            self.check_monotonic(sensor, time_us)?;
            self.check_limits(time_us)?;
            return Ok(Some(TrackerSample {
                time_us,
                sensor,
                position,
                orientation,
            }));
        }
    }

    fn check_header(&self, fields: &[String]) -> Result<(), ImportError> {
        let matches = fields.len() == self.header.len()
            && fields
                .iter()
                .zip(self.header)
                .all(|(f, h)| f.eq_ignore_ascii_case(h));
        if matches {
            Ok(())
        } else {
            Err(self.lines.syntax(
                "header",
                &format!("{:?}", self.header.join(",")),
                Some(&fields.join(",")),
            ))
        }
    }

    fn time(&self, token: Option<&str>) -> Result<u64, ImportError> {
        let field = self.header.first().copied().unwrap_or("time");
        let token = token.unwrap_or("");
        token.parse().map_err(|_| {
            self.lines
                .syntax(field, "an unsigned integer (microseconds)", Some(token))
        })
    }

    fn sensor(&self, token: Option<&str>) -> Result<u8, ImportError> {
        let token = token.unwrap_or("");
        token.parse().map_err(|_| {
            self.lines
                .syntax("sensor", "an integer 0..=255", Some(token))
        })
    }

    fn float(&self, token: Option<&str>, field: &str) -> Result<f64, ImportError> {
        self.lines.number_f64(token.unwrap_or(""), field)
    }

    fn quaternion(&self, fields: &[&str], names: [&str; 4]) -> Result<DQuat, ImportError> {
        let mut wxyz = [0.0; 4];
        for ((slot, name), token) in wxyz.iter_mut().zip(names).zip(
            fields
                .iter()
                .copied()
                .map(Some)
                .chain(std::iter::repeat(None)),
        ) {
            *slot = self.float(token, name)?;
        }
        let [w, x, y, z] = wxyz;
        let q = DQuat::from_xyzw(x, y, z, w);
        let norm = q.length();
        if (norm - 1.0).abs() > NORM_TOLERANCE {
            let problem = format!("norm {norm} is not within {NORM_TOLERANCE} of 1");
            return Err(self.lines.invalid(&names.join(","), problem));
        }
        Ok(q / norm)
    }

    /// [`MAX_SAMPLES`] and [`MAX_SPAN_US`].
    fn check_limits(&mut self, time_us: u64) -> Result<(), ImportError> {
        let field = self.header.first().copied().unwrap_or("time");
        self.count += 1;
        if self.count > self.max_samples {
            let problem = format!(
                "more than {} samples (the most one recording holds)",
                self.max_samples
            );
            return Err(self.lines.invalid(field, problem));
        }
        let (lo, hi) = self.span.unwrap_or((time_us, time_us));
        let (lo, hi) = (lo.min(time_us), hi.max(time_us));
        if hi - lo > MAX_SPAN_US {
            let problem = format!(
                "{time_us} us is more than {MAX_SPAN_US} us (71 min 35 s, the range of the wire's \
                 microsecond clock) from another sample's {} us",
                if time_us == lo { hi } else { lo }
            );
            return Err(self.lines.invalid(field, problem));
        }
        self.span = Some((lo, hi));
        Ok(())
    }

    fn check_monotonic(&mut self, sensor: u8, time_us: u64) -> Result<(), ImportError> {
        let line = self.lines.number();
        let slot = self.last.get_mut(usize::from(sensor));
        let previous = slot.as_ref().and_then(|s| **s);
        if let Some((before, before_line)) = previous
            && time_us <= before
        {
            let problem = format!(
                "{time_us} us is not after sensor {sensor}'s previous sample ({before} us, line {before_line})"
            );
            return Err(self
                .lines
                .invalid(self.header.first().copied().unwrap_or("time"), problem));
        }
        if let Some(s) = slot {
            *s = Some((time_us, line));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_optional_comments_and_normalisation() {
        let with = "# recorded by hand\ntime_us,sensor,x,y,z,qw,qx,qy,qz\n0,1,0.5,1,2,1,0,0,0\n\n10, 1, 0,0,0, 0,0,0,1.0005\n";
        let a = parse_tracker_csv(with.as_bytes(), "a.csv").unwrap();
        assert_eq!(a.len(), 2);
        assert_eq!(a[0].sensor, 1);
        assert_eq!(a[0].position, DVec3::new(0.5, 1.0, 2.0));
        assert_eq!(a[1].orientation, DQuat::from_xyzw(0.0, 0.0, 1.0, 0.0));
        let without = "0,1,0.5,1,2,1,0,0,0\n";
        assert_eq!(
            parse_tracker_csv(without.as_bytes(), "b.csv").unwrap()[0],
            a[0]
        );
    }

    #[test]
    fn interleaved_sensors_and_roundtrip() {
        let text = "5,0,0,0,0,1,0,0,0\n3,1,0,0,0,1,0,0,0\n6,0,0,0,0,1,0,0,0\n";
        let samples = parse_tracker_csv(text.as_bytes(), "c.csv").unwrap();
        let mut out = Vec::new();
        write_tracker_csv(&mut out, &samples).unwrap();
        assert_eq!(parse_tracker_csv(out.as_slice(), "d.csv").unwrap(), samples);
        let merged = merge_by_time(vec![samples]);
        assert_eq!(
            merged.iter().map(|s| s.time_us).collect::<Vec<_>>(),
            [3, 5, 6]
        );
    }

    #[test]
    fn time_going_backwards_names_the_line() {
        let text = "5,0,0,0,0,1,0,0,0\n5,0,0,0,0,1,0,0,0\n";
        let err = parse_tracker_csv(text.as_bytes(), "e.csv").unwrap_err();
        assert_eq!(err.line(), Some(2));
        assert!(err.to_string().contains("line 1"), "{err}");
    }

    #[test]
    fn time_stamps_beyond_the_wire_clock_name_the_line() {
        let max = u64::MAX;
        let text = format!("0,0,0,0,0,1,0,0,0\n{max},0,0,0,0,1,0,0,0\n");
        let err = parse_tracker_csv(text.as_bytes(), "e.csv").unwrap_err();
        assert_eq!(err.line(), Some(2));
        assert!(err.to_string().contains("71 min"), "{err}");
        // Exactly the span still reads, from any epoch, any sensor order.
        let edge = MAX_SPAN_US + 7;
        let text = format!("{edge},1,0,0,0,1,0,0,0\n7,0,0,0,0,1,0,0,0\n");
        assert_eq!(
            parse_tracker_csv(text.as_bytes(), "e.csv").unwrap().len(),
            2
        );
        let text = format!("{},1,0,0,0,1,0,0,0\n7,0,0,0,0,1,0,0,0\n", edge + 1);
        assert!(parse_tracker_csv(text.as_bytes(), "e.csv").is_err());
    }

    #[test]
    fn more_samples_than_the_limit_stop_the_reading() {
        let rows = (0..=100).map(|t| format!("{t},0,0,0,0,1,0,0,0\n"));
        let text: String = rows.collect();
        let reader = TrackerReader::new(text.as_bytes(), "big.csv").with_limit(100);
        let err = reader.collect::<Result<Vec<_>, _>>().unwrap_err();
        assert_eq!(err.line(), Some(101));
        assert!(err.to_string().contains("more than"), "{err}");
    }

    #[test]
    fn xio_shape() {
        let text = "Timestamp (us),W,X,Y,Z\n917418209,0.850093,-0.040743,-0.524145,-0.034592\n917438268,0.850149,-0.040586,-0.524089,-0.034260\n";
        let s = parse_xio_quaternions(text.as_bytes(), "x.csv", 3).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s[1].time_us, 917_438_268);
        assert_eq!(s[0].sensor, 3);
        assert_eq!(s[0].position, DVec3::ZERO);
        assert!((s[0].orientation.length() - 1.0).abs() < 1e-12);
        // normalised: the file's norm is 1.00012
        assert!(
            (s[0].orientation.w - 0.850093 / 1.000_120_9).abs() < 1e-6,
            "{}",
            s[0].orientation
        );
        let no_header = "917418209,0.850093,-0.040743,-0.524145,-0.034592\n";
        assert_eq!(
            parse_xio_quaternions(no_header.as_bytes(), "x.csv", 3)
                .unwrap_err()
                .line(),
            Some(1)
        );
    }
}
