//! Helpers shared by the end-to-end test files (each test file is its own crate and uses a
//! different subset, hence the `dead_code` allowance).
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use psao_wire::{decode_frame, Message, HEADER_LEN};

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

/// `psao --log warn <role> --scene SCENE <server> <extra>`, running, with the first line of
/// its standard output (a server's `listening on ADDR`) once printed.
pub fn start_role(role: &str, scene: &str, server: &[&str], extra: &[&str]) -> (Proc, String) {
    let mut child = Command::new(BIN)
        .args(["--log", "warn", role, "--scene", scene])
        .args(server)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    (Proc(child), line.trim().to_string())
}

/// The address of a server that printed `listening on ADDR` (the line of [`start_role`]).
pub fn listening_addr(line: &str) -> String {
    line.trim()
        .strip_prefix("listening on ")
        .unwrap_or_else(|| panic!("unexpected output {line:?}"))
        .to_string()
}

/// Sends `bytes` to the server at `addr`, closes the sending side, and reads what it answers
/// until it closes (within `deadline` per read): the decoded messages.
pub fn exchange(addr: &str, bytes: &[u8], deadline: Duration) -> Vec<Message> {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(deadline)).unwrap();
    s.write_all(bytes).unwrap();
    let _ = s.shutdown(std::net::Shutdown::Write);
    let mut all = Vec::new();
    s.read_to_end(&mut all)
        .expect("the server closes the session");
    let mut out = Vec::new();
    let mut rest = &all[..];
    while rest.len() >= HEADER_LEN {
        let len = u32::from_le_bytes(rest[4..8].try_into().unwrap()) as usize;
        let (frame, tail) = rest.split_at(HEADER_LEN + len);
        out.push(decode_frame(frame, 1 << 28).unwrap());
        rest = tail;
    }
    out
}
