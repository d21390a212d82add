//! The recorder: lines in order, bad input counted, and no line that returned lost.

use super::output::Sink;
use super::*;
use crate::radio::Reading;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::Path;

fn sample(t: u64, x: f64) -> SensorSample {
    SensorSample { timestamp_ns: t, x, y: -0.0, z: 9.81 }
}

fn wifi(bssid: &str, rssi_dbm: f64, age_ns: u64) -> Reading {
    Reading { transmitter: TransmitterId::wifi(bssid).unwrap(), rssi_dbm, age_ns }
}

fn options() -> RecorderOptions {
    RecorderOptions { walk_name: "walk".into(), site_id: "office".into(), device: "Google Pixel 8".into() }
}

#[test]
fn lines_before_the_first_waypoint_go_to_its_floor_and_a_floor_change_begins_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
    r.push_accelerometer(&[sample(1_000, 0.1), sample(2_000, 0.2)]).unwrap();
    r.push_scan(&Scan { timestamp_ns: 2_500, readings: vec![wifi("aa:bb:cc:dd:ee:01", -61.5, 500)] })
        .unwrap();
    r.mark_waypoint(3_000, 1.0, 2.0, "F1").unwrap();
    r.push_gyroscope(&[sample(3_500, 0.01)]).unwrap();
    r.mark_waypoint(9_000, 4.0, 2.0, "F2").unwrap();
    let stats = r.finish().unwrap();
    assert_eq!(stats.files.len(), 2);
    assert!(stats.files[0].ends_with("F1/path_data_files/walk-1.txt"));
    assert!(stats.files[1].ends_with("F2/path_data_files/walk-2.txt"));
    let first = std::fs::read_to_string(&stats.files[0]).unwrap();
    let lines: Vec<&str> = first.lines().collect();
    assert_eq!(lines[0], "#\tstartTime:1000");
    assert!(lines[1].contains("SiteID:office") && lines[1].contains("FloorName:F1"));
    assert_eq!(lines[2], "#\tBrand:Google\tModel:Pixel 8");
    assert!(lines[3].starts_with(&format!("#\t{RECORDER_HEADER}")));
    assert_eq!(lines[4], "1000\tTYPE_ACCELEROMETER\t0.1\t-0\t9.81");
    assert_eq!(lines[6], "2500\tTYPE_WIFI\t\taa:bb:cc:dd:ee:01\t-61.5\t0\t2000");
    assert_eq!(lines[7], "3000\tTYPE_WAYPOINT\t1\t2");
    assert_eq!(lines[8], "3500\tTYPE_GYROSCOPE\t0.01\t-0\t9.81");
    assert_eq!(*lines.last().unwrap(), "#\tendTime:3500", "the last line before the floor changed");
    let second = std::fs::read_to_string(&stats.files[1]).unwrap();
    assert!(second.contains("FloorName:F2") && second.contains("9000\tTYPE_WAYPOINT\t4\t2"));
    assert!(second.starts_with("#\tstartTime:9000\n") && second.ends_with("#\tendTime:9000\n"));
}

#[test]
fn bad_input_is_dropped_or_rejected_and_counted_never_written() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
    let report = r
        .push_magnetometer(&[sample(10, 1.0), sample(10, 2.0), sample(5, 3.0), sample(20, f64::NAN)])
        .unwrap();
    assert_eq!((report.accepted, report.out_of_order, report.non_finite), (1, 2, 1));
    assert!(matches!(r.push_scan(&Scan { timestamp_ns: 30, readings: vec![] }), Err(RecorderError::Scan(_))));
    let nan = Scan { timestamp_ns: 30, readings: vec![wifi("aa:bb:cc:dd:ee:01", f64::NAN, 0)] };
    assert!(matches!(r.push_scan(&nan), Err(RecorderError::Scan(_))));
    let ok = Scan { timestamp_ns: 30, readings: vec![wifi("aa:bb:cc:dd:ee:01", -70.0, 0)] };
    r.push_scan(&ok).unwrap();
    assert!(matches!(r.push_scan(&ok), Err(RecorderError::Scan(_))), "a duplicate scan");
    let hashed = Scan {
        timestamp_ns: 40,
        readings: vec![Reading {
            transmitter: TransmitterId::HashedWifi { hash: "0".repeat(32) },
            rssi_dbm: -70.0,
            age_ns: 0,
        }],
    };
    assert!(matches!(r.push_scan(&hashed), Err(RecorderError::Scan(_))));
    assert!(matches!(r.mark_waypoint(50, f64::INFINITY, 0.0, "F1"), Err(RecorderError::Waypoint(_))));
    assert!(matches!(r.mark_waypoint(50, 0.0, 0.0, "../F1"), Err(RecorderError::InvalidName { .. })));
    assert!(matches!(r.mark_waypoint(50, 0.0, 0.0, ""), Err(RecorderError::InvalidName { .. })));
    r.mark_waypoint(50, 0.0, 0.0, "F1").unwrap();
    assert!(matches!(r.mark_waypoint(49, 0.0, 0.0, "F1"), Err(RecorderError::Waypoint(_))));
    let stats = r.finish().unwrap();
    assert_eq!((stats.samples, stats.samples_out_of_order, stats.samples_non_finite), (1, 2, 1));
    assert_eq!((stats.scans, stats.scans_rejected, stats.waypoints), (1, 4, 1));
    let text = std::fs::read_to_string(&stats.files[0]).unwrap();
    assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 3);
    assert!(matches!(r.push_accelerometer(&[sample(60, 1.0)]), Err(RecorderError::Finished)));
    assert!(matches!(r.finish(), Err(RecorderError::Finished)));
}

#[test]
fn names_that_cannot_be_files_are_refused_and_files_are_never_overwritten() {
    let dir = tempfile::tempdir().unwrap();
    for bad in ["", " ", "..", "a/b", "a\\b", "tab\there"] {
        let bad_walk = RecorderOptions { walk_name: bad.into(), ..options() };
        assert!(
            matches!(SurveyRecorder::new(dir.path(), bad_walk), Err(RecorderError::InvalidName { .. })),
            "{bad:?}"
        );
    }
    let bad_site = RecorderOptions { site_id: "a\nb".into(), ..options() };
    assert!(matches!(SurveyRecorder::new(dir.path(), bad_site), Err(RecorderError::InvalidName { .. })));
    let mut a = SurveyRecorder::new(dir.path(), options()).unwrap();
    a.mark_waypoint(1, 0.0, 0.0, "F1").unwrap();
    a.finish().unwrap();
    let mut b = SurveyRecorder::new(dir.path(), options()).unwrap();
    assert!(matches!(b.mark_waypoint(1, 0.0, 0.0, "F1"), Err(RecorderError::Io { .. })));
    let mut none =
        SurveyRecorder::new(dir.path(), RecorderOptions { walk_name: "empty".into(), ..options() }).unwrap();
    none.push_accelerometer(&[sample(1, 0.0)]).unwrap();
    assert!(matches!(none.finish(), Err(RecorderError::NoWaypoints)));
}

/// A disk that fills up on cue: writes succeed while `space` lasts (the last one in part,
/// as a real full disk does), then fail with ENOSPC; truncation and opening can be made to
/// fail too. The files are real, so tests read what a reader would.
#[derive(Default)]
struct Faults {
    space: u64,
    truncate_fails: bool,
    open_fails: bool,
    sync_fails: bool,
    syncs: u64,
}

struct FaultySink {
    file: File,
    faults: std::sync::Arc<std::sync::Mutex<Faults>>,
}

impl Write for FaultySink {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut faults = self.faults.lock().unwrap();
        if faults.space == 0 {
            return Err(io::Error::from_raw_os_error(28));
        }
        let n = buf.len().min(faults.space as usize);
        faults.space -= n as u64;
        self.file.write(&buf[..n])
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Sink for FaultySink {
    fn sync(&mut self) -> io::Result<()> {
        let mut faults = self.faults.lock().unwrap();
        if faults.sync_fails {
            return Err(io::Error::from_raw_os_error(5));
        }
        faults.syncs += 1;
        self.file.sync_data()
    }

    fn truncate(&mut self, len: u64) -> io::Result<()> {
        match self.faults.lock().unwrap().truncate_fails {
            true => Err(io::Error::from_raw_os_error(5)),
            false => self.file.set_len(len),
        }
    }
}

fn faulty(dir: &Path) -> (SurveyRecorder, std::sync::Arc<std::sync::Mutex<Faults>>) {
    let faults = std::sync::Arc::new(std::sync::Mutex::new(Faults { space: u64::MAX, ..Faults::default() }));
    let shared = faults.clone();
    let open: Opener = Box::new(move |path| {
        if shared.lock().unwrap().open_fails {
            return Err(io::Error::from_raw_os_error(13));
        }
        let file = OpenOptions::new().append(true).create_new(true).open(path)?;
        Ok(Box::new(FaultySink { file, faults: shared.clone() }) as Box<dyn Sink>)
    });
    (SurveyRecorder::with_opener(dir.to_owned(), options(), open).unwrap(), faults)
}

fn data_lines(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.is_empty() || text.ends_with('\n'), "a file ends mid-line: {text:?}");
    text.lines().filter(|l| !l.starts_with('#')).map(str::to_owned).collect()
}

fn batch(from: u64, n: u64) -> Vec<SensorSample> {
    (from..from + n).map(|k| sample(k * 10_000_000, 0.5)).collect()
}

#[test]
fn a_full_disk_fails_every_call_until_resumed_and_loses_nothing_that_returned_ok() {
    let dir = tempfile::tempdir().unwrap();
    let (mut r, faults) = faulty(dir.path());
    r.push_accelerometer(&batch(0, 10)).unwrap();
    r.mark_waypoint(100_000_000, 1.0, 2.0, "F1").unwrap();
    r.push_accelerometer(&batch(11, 10)).unwrap();
    let before = r.stats().clone();
    faults.lock().unwrap().space = 40; // a line and a half
    assert!(matches!(r.push_accelerometer(&batch(21, 10)), Err(RecorderError::Io { .. })));
    let path = r.stats().files[0].clone();
    assert_eq!(data_lines(&path).len(), 21, "the failed call's partial line was cut back");
    assert_eq!(r.stats(), &before, "a failed call counts nothing");
    // Space again, but the error sticks until the app acknowledges it.
    faults.lock().unwrap().space = u64::MAX;
    assert!(matches!(r.push_accelerometer(&batch(21, 10)), Err(RecorderError::Io { .. })));
    assert!(matches!(r.mark_waypoint(400_000_000, 1.0, 2.0, "F1"), Err(RecorderError::Io { .. })));
    assert!(matches!(r.finish(), Err(RecorderError::Io { .. })), "not finished, so it can be retried");
    assert_eq!(r.stats(), &before);
    r.resume().unwrap();
    assert_eq!(r.push_accelerometer(&batch(21, 10)).unwrap().accepted, 10, "the failed batch again");
    r.mark_waypoint(400_000_000, 1.0, 2.0, "F1").unwrap();
    let stats = r.finish().unwrap();
    assert_eq!((stats.samples, stats.waypoints), (30, 2));
    let lines = data_lines(&path);
    assert_eq!(lines.len(), 32);
    let times: Vec<u64> = lines.iter().map(|l| l.split('\t').next().unwrap().parse().unwrap()).collect();
    let mut sorted = times.clone();
    sorted.dedup();
    assert_eq!(sorted.len(), times.len(), "no line twice");
    assert!(std::fs::read_to_string(&path).unwrap().ends_with("#\tendTime:400000000\n"));
}

#[test]
fn a_partial_line_that_could_not_be_cut_back_is_cut_at_resume() {
    let dir = tempfile::tempdir().unwrap();
    let (mut r, faults) = faulty(dir.path());
    r.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
    {
        let mut f = faults.lock().unwrap();
        (f.space, f.truncate_fails) = (15, true);
    }
    assert!(matches!(r.push_gyroscope(&batch(1, 3)), Err(RecorderError::Io { .. })));
    let path = r.stats().files[0].clone();
    assert!(!std::fs::read_to_string(&path).unwrap().ends_with('\n'), "the fault left half a line");
    faults.lock().unwrap().space = u64::MAX;
    assert!(matches!(r.resume(), Err(RecorderError::Io { .. })), "still cannot cut it back");
    assert!(matches!(r.push_gyroscope(&batch(1, 3)), Err(RecorderError::Io { .. })));
    faults.lock().unwrap().truncate_fails = false;
    r.resume().unwrap();
    assert_eq!(data_lines(&path).len(), 1);
    r.push_gyroscope(&batch(1, 3)).unwrap();
    r.finish().unwrap();
    assert_eq!(data_lines(&path).len(), 4);
}

#[test]
fn lines_that_cannot_be_synced_are_cut_back_and_finish_can_be_retried() {
    let dir = tempfile::tempdir().unwrap();
    let (mut r, faults) = faulty(dir.path());
    r.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
    r.push_accelerometer(&batch(1, 5)).unwrap();
    faults.lock().unwrap().sync_fails = true;
    assert!(matches!(r.finish(), Err(RecorderError::Io { .. })));
    let path = r.stats().files[0].clone();
    assert!(!std::fs::read_to_string(&path).unwrap().contains("endTime"), "the unsynced end line is cut");
    faults.lock().unwrap().sync_fails = false;
    r.resume().unwrap();
    r.finish().unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.matches("endTime").count(), 1);
    assert_eq!(data_lines(&path).len(), 6);
}

#[test]
fn a_floor_change_that_fails_leaves_the_previous_file_current() {
    let dir = tempfile::tempdir().unwrap();
    let (mut r, faults) = faulty(dir.path());
    r.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
    faults.lock().unwrap().open_fails = true;
    assert!(matches!(r.mark_waypoint(10, 1.0, 2.0, "F2"), Err(RecorderError::Io { .. })));
    assert!(matches!(r.push_magnetometer(&batch(2, 1)), Err(RecorderError::Io { .. })));
    faults.lock().unwrap().open_fails = false;
    r.resume().unwrap();
    r.push_magnetometer(&batch(2, 1)).unwrap();
    // The new file cannot be written in full: it is removed, the old one goes on.
    faults.lock().unwrap().space = 100;
    let header_and_first = r.mark_waypoint(30_000_000, 1.0, 2.0, "F2");
    assert!(matches!(header_and_first, Err(RecorderError::Io { .. })));
    assert!(!dir.path().join("F2/path_data_files/walk-2.txt").exists());
    faults.lock().unwrap().space = u64::MAX;
    r.resume().unwrap();
    r.mark_waypoint(30_000_000, 1.0, 2.0, "F2").unwrap();
    let stats = r.finish().unwrap();
    assert_eq!(stats.files.len(), 2);
    assert_eq!(data_lines(&stats.files[0]).len(), 2);
    assert_eq!(data_lines(&stats.files[1]).len(), 1);
    let first = std::fs::read_to_string(&stats.files[0]).unwrap();
    assert_eq!(first.matches("endTime").count(), 1);
}

#[test]
fn input_before_the_first_waypoint_is_spooled_to_disk_and_files_are_synced() {
    let dir = tempfile::tempdir().unwrap();
    let (mut r, faults) = faulty(dir.path());
    r.push_accelerometer(&batch(0, 100)).unwrap();
    let spool = dir.path().join(".walk.pending");
    assert_eq!(data_lines(&spool).len(), 100, "on disk, not in memory");
    assert!(matches!(r.finish(), Err(RecorderError::NoWaypoints)));
    r.push_accelerometer(&batch(100, 1)).unwrap();
    let syncs = faults.lock().unwrap().syncs;
    r.mark_waypoint(2_000_000_000, 0.0, 0.0, "F1").unwrap();
    assert!(faults.lock().unwrap().syncs > syncs, "a new file is synced");
    assert!(!spool.exists(), "its lines are in the walk file");
    let syncs = faults.lock().unwrap().syncs;
    let stats = r.finish().unwrap();
    assert!(faults.lock().unwrap().syncs > syncs, "the end is synced");
    assert_eq!(data_lines(&stats.files[0]).len(), 102);
    assert!(std::fs::read_to_string(&stats.files[0]).unwrap().starts_with("#\tstartTime:0\n"));
}

#[test]
fn an_unusable_directory_fails_the_first_write_and_every_call_after() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a file");
    std::fs::write(&file, "").unwrap();
    let mut r = SurveyRecorder::new(file.join("walks"), options()).unwrap();
    assert!(matches!(r.push_accelerometer(&[sample(1, 0.0)]), Err(RecorderError::Io { .. })));
    assert!(matches!(r.push_accelerometer(&[sample(2, 0.0)]), Err(RecorderError::Io { .. })));
    assert!(matches!(r.mark_waypoint(3, 0.0, 0.0, "F1"), Err(RecorderError::Io { .. })));
    assert!(matches!(r.finish(), Err(RecorderError::Io { .. })));
    r.resume().unwrap();
    assert!(matches!(r.push_accelerometer(&[sample(4, 0.0)]), Err(RecorderError::Io { .. })), "still");
    assert_eq!(r.stats().samples, 0);
}

#[test]
fn floor_names_that_would_share_a_folder_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
    for bad in ["F1 ", " F1", "F1."] {
        let refused = r.mark_waypoint(1, 0.0, 0.0, bad);
        assert!(matches!(refused, Err(RecorderError::InvalidName { .. })), "{bad:?}");
    }
    r.mark_waypoint(1, 0.0, 0.0, "F1").unwrap();
    let refused = r.mark_waypoint(2, 0.0, 0.0, "f1");
    assert!(matches!(refused, Err(RecorderError::InvalidName { .. })), "only the case differs");
    r.mark_waypoint(3, 0.0, 0.0, "F2").unwrap();
    r.mark_waypoint(4, 0.0, 0.0, "F1").unwrap();
    let stats = r.finish().unwrap();
    assert_eq!(stats.files.len(), 3);
    let mut other =
        SurveyRecorder::new(dir.path(), RecorderOptions { walk_name: "b".into(), ..options() }).unwrap();
    let refused = other.mark_waypoint(1, 0.0, 0.0, "f2");
    assert!(matches!(refused, Err(RecorderError::InvalidName { .. })), "a folder of another walk");
}

#[test]
fn a_time_far_ahead_is_refused_and_counted_and_the_stream_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
    r.push_accelerometer(&batch(0, 10)).unwrap();
    let negative = sample(u64::MAX - 999, 0.5);
    let report = r.push_accelerometer(&[negative]).unwrap();
    assert_eq!((report.accepted, report.ahead), (0, 1));
    assert_eq!(r.push_accelerometer(&batch(10, 100)).unwrap().accepted, 100);
    let hour = 3_600_000_000_000;
    let report = r.push_accelerometer(&[sample(hour, 0.5)]).unwrap();
    assert_eq!(report.ahead, 1, "more than 10 s ahead of the clock");
    assert_eq!(r.push_accelerometer(&batch(110, 1)).unwrap().accepted, 1);
    // A real jump (the phone slept): the next sample confirms the first.
    let report = r.push_accelerometer(&[sample(2 * hour, 0.5), sample(2 * hour + 10, 0.5)]).unwrap();
    assert_eq!((report.accepted, report.ahead), (1, 1));
    let scan = Scan { timestamp_ns: u64::MAX - 8, readings: vec![wifi("aa:bb:cc:dd:ee:01", -70.0, 0)] };
    assert!(matches!(r.push_scan(&scan), Err(RecorderError::Scan(_))));
    let scan = Scan { timestamp_ns: 2 * hour + 20, readings: vec![wifi("aa:bb:cc:dd:ee:01", -70.0, 0)] };
    r.push_scan(&scan).unwrap();
    assert!(matches!(r.mark_waypoint(u64::MAX, 0.0, 0.0, "F1"), Err(RecorderError::Waypoint(_))));
    r.mark_waypoint(2 * hour + 30, 0.0, 0.0, "F1").unwrap();
    let stats = r.finish().unwrap();
    assert_eq!((stats.samples, stats.samples_ahead, stats.scans_rejected), (112, 3, 1));
}
