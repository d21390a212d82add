//! The survey recorder's durability against a real process and a real disk
//! (docs/surveying.md#durability): an app killed with SIGKILL loses no call that returned, before
//! or after the first waypoint; and on a filesystem that fills up, no call that returned is lost,
//! the files hold whole lines, and the error sticks until the app resumes.
//!
//! The test binary runs itself again as the child process, with `CHILD` naming what the child
//! does; `child_process` is that entry point and does nothing in a normal run.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use waymark_engine::recorder::{RecorderOptions, SurveyRecorder};
use waymark_engine::sensors::SensorSample;
use waymark_engine::RecorderError;

const CHILD: &str = "WAYMARK_RECORDER_CHILD";
const DIR: &str = "WAYMARK_RECORDER_DIR";
/// The batches the child pushes before it idles.
const ACKED: u64 = 300;

fn options() -> RecorderOptions {
    RecorderOptions { walk_name: "walk".into(), site_id: "site".into(), device: "Test Phone".into() }
}

/// Batch `k`: ten accelerometer samples 10 ms apart.
fn batch(k: u64) -> Vec<SensorSample> {
    (0..10)
        .map(|j| SensorSample { timestamp_ns: (k * 10 + j) * 10_000_000, x: 0.1, y: 0.2, z: 9.81 })
        .collect()
}

/// The samples' times in `path`, from its whole lines.
fn sample_times(path: &Path) -> Vec<u64> {
    let text = std::fs::read_to_string(path).unwrap();
    text.split_inclusive('\n')
        .filter(|l| l.ends_with('\n') && l.contains("TYPE_ACCELEROMETER"))
        .map(|l| l.split('\t').next().unwrap().parse().unwrap())
        .collect()
}

/// The child's side: what `CHILD` says, in the folder `DIR`.
#[test]
fn child_process() {
    let (Ok(mode), Ok(dir)) = (std::env::var(CHILD), std::env::var(DIR)) else { return };
    match mode.as_str() {
        "killed-before-waypoint" | "killed-after-waypoint" => record_until_killed(&mode, Path::new(&dir)),
        "full-disk" => fill_the_disk(Path::new(&dir)),
        _ => panic!("unknown child mode {mode}"),
    }
}

/// Pushes batches 0 to `ACKED`, printing `ack K` once batch K's call returned, then idles.
fn record_until_killed(mode: &str, dir: &Path) {
    let mut recorder = SurveyRecorder::new(dir, options()).unwrap();
    if mode == "killed-after-waypoint" {
        recorder.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
    }
    for k in 0..=ACKED {
        recorder.push_accelerometer(&batch(k)).unwrap();
        println!("ack {k}");
    }
    // Idle, as an app between sensor batches, until killed: nothing later flushes the earlier.
    loop {
        std::thread::sleep(std::time::Duration::from_secs(1));
    }
}

/// Runs the child in `mode` until it acknowledged batch `acks`, then kills it with SIGKILL.
fn run_until_acked(mode: &str, dir: &Path, acks: u64) {
    let exe = std::env::current_exe().unwrap();
    let mut child = Command::new(exe)
        .args(["--exact", "child_process", "--nocapture", "--test-threads=1"])
        .env(CHILD, mode)
        .env(DIR, dir)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = BufReader::new(child.stdout.take().unwrap());
    for line in stdout.lines() {
        if line.unwrap() == format!("ack {acks}") {
            break;
        }
    }
    // Child::kill sends SIGKILL on Unix: no destructor, no flush runs in the child.
    child.kill().unwrap();
    child.wait().unwrap();
}

#[cfg(unix)]
#[test]
fn a_killed_app_loses_no_call_that_returned() {
    for (mode, path) in [
        ("killed-before-waypoint", ".walk.pending"),
        ("killed-after-waypoint", "F1/path_data_files/walk-1.txt"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        run_until_acked(mode, dir.path(), ACKED);
        let times = sample_times(&dir.path().join(path));
        let wanted: Vec<u64> = (0..=ACKED).flat_map(batch).map(|s| s.timestamp_ns).collect();
        assert_eq!(times.len(), wanted.len(), "{mode}: samples on disk of those acknowledged");
        assert_eq!(times, wanted, "{mode}");
    }
}

/// Runs `script` (with `args` as `$1`...) in a mount namespace of its own; `None` where
/// `unshare` cannot run.
fn in_mount_namespace(script: &str, args: &[&str]) -> Option<std::process::ExitStatus> {
    Command::new("unshare").args(["-m", "sh", "-c", script, "sh"]).args(args).status().ok()
}

/// A real full disk: a 256 KiB tmpfs, mounted in a mount namespace of the child's own. Where
/// that is not allowed (not root, no `unshare`, a container without `mount`) it says so and
/// checks nothing; the same faults are injected in `src/recorder.rs`'s tests (this crate's)
/// everywhere.
#[cfg(target_os = "linux")]
#[test]
fn a_full_filesystem_loses_no_call_that_returned() {
    let dir = tempfile::tempdir().unwrap();
    let dir_arg = dir.path().to_str().unwrap();
    let probe = in_mount_namespace("mount -t tmpfs -o size=16k tmpfs \"$1\"", &[dir_arg]);
    if !probe.is_some_and(|s| s.success()) {
        eprintln!("skipped: cannot mount a tmpfs in a mount namespace here");
        return;
    }
    let exe = std::env::current_exe().unwrap();
    let status = Command::new("unshare")
        .args(["-m", "sh", "-c", "mount -t tmpfs -o size=256k tmpfs \"$1\" && exec \"$2\" \"$@\"", "sh"])
        .arg(dir.path())
        .arg(exe)
        .args(["--exact", "child_process", "--nocapture", "--test-threads=1"])
        .env(CHILD, "full-disk")
        .env(DIR, dir.path())
        .status()
        .unwrap();
    assert!(status.success(), "the child's checks failed: {status}");
}

/// In the child, on the 256 KiB tmpfs: records until the disk is full, then frees space.
fn fill_the_disk(dir: &Path) {
    let ballast = dir.join("ballast");
    std::fs::write(&ballast, vec![0u8; 64 * 1024]).unwrap();
    let mut recorder = SurveyRecorder::new(dir, options()).unwrap();
    recorder.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
    let path = recorder.stats().files[0].clone();
    let mut k = 0;
    let failed = loop {
        match recorder.push_accelerometer(&batch(k)) {
            Ok(_) => k += 1,
            Err(e) => break e,
        }
        assert!(k < 100_000, "the disk never filled");
    };
    assert!(matches!(failed, RecorderError::Io { .. }), "{failed}");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.ends_with('\n'), "the file ends mid-line");
    assert_eq!(sample_times(&path).len() as u64, k * 10, "every call that returned, and no more");
    assert_eq!(recorder.stats().samples, k * 10, "counts only what was written");
    std::fs::remove_file(&ballast).unwrap();
    assert!(matches!(recorder.push_accelerometer(&batch(k)), Err(RecorderError::Io { .. })), "it sticks");
    assert!(matches!(recorder.finish(), Err(RecorderError::Io { .. })), "not finished: it can retry");
    recorder.resume().unwrap();
    recorder.push_accelerometer(&batch(k)).unwrap();
    recorder.mark_waypoint((k * 10 + 9) * 10_000_000, 1.0, 2.0, "F1").unwrap();
    let stats = recorder.finish().unwrap();
    let wanted: Vec<u64> = (0..=k).flat_map(batch).map(|s| s.timestamp_ns).collect();
    assert_eq!(sample_times(&path), wanted);
    assert_eq!(stats.samples, (k + 1) * 10);
    let end = format!("#\tendTime:{}\n", (k * 10 + 9) * 10_000_000);
    assert!(std::fs::read_to_string(&path).unwrap().ends_with(&end));
}
