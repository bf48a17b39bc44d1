//! Helpers shared by the end-to-end test files (each test file is its own crate and uses a
//! different subset, hence the `dead_code` allowance).
#![allow(dead_code)]

use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Output};

/// Path of the `psao` binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_psao");

/// Runs `psao --log warn ARGS` to completion.
pub fn psao(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(["--log", "warn"])
        .args(args)
        .output()
        .expect("the psao binary runs")
}

/// The process's standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A JSON file, parsed.
pub fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A free port on 127.0.0.1 (bound once and released).
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A child process killed on drop.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}
