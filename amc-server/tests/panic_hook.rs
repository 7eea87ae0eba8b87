//! The service's panic hook logs a panic once, through the log, with its
//! message, location, thread and backtrace (its own process: the hook is
//! global).

use std::io::Write;
use std::sync::{Arc, Mutex};

#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[test]
fn a_panic_is_logged_with_its_location_and_backtrace() {
    let log = Captured::default();
    let writer = log.clone();
    tracing_subscriber::fmt()
        .json()
        .with_writer(move || writer.clone())
        .init();
    amc_server::serve::panics::install_hook();
    let worker = std::thread::Builder::new()
        .name("worker-7".into())
        .spawn(|| {
            if std::hint::black_box(true) {
                panic!("test-only trigger: boom {}", 42);
            }
        })
        .unwrap();
    let payload = worker.join().expect_err("the thread panicked");
    assert_eq!(
        amc_server::serve::panics::payload_text(payload.as_ref()),
        "test-only trigger: boom 42"
    );
    let text = String::from_utf8(log.0.lock().unwrap().clone()).unwrap();
    let events: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(events.len(), 1, "{text}");
    let e = &events[0];
    assert_eq!(e["level"], "ERROR", "{e}");
    assert_eq!(e["target"], "amc::panic", "{e}");
    let f = &e["fields"];
    assert_eq!(f["message"], "panic", "{e}");
    assert_eq!(f["payload"], "test-only trigger: boom 42", "{e}");
    assert!(
        f["location"].as_str().unwrap().contains("panic_hook.rs"),
        "{e}"
    );
    assert_eq!(f["thread"], "worker-7", "{e}");
    assert!(
        f["backtrace"]
            .as_str()
            .unwrap()
            .contains("a_panic_is_logged_with_its_location_and_backtrace"),
        "{e}"
    );
}
