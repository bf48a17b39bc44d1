//! `psao serve --relight` on a scene with one skinned character (CesiumMan from the shared
//! data, skipped when missing): `/characters/N.prt` (token-guarded, 404 out of range), the
//! relighting message after the welcome only for clients announcing it, the model cache
//! reused on the next start, and `psao view` of it showing the frames of `psao run --relight`.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

mod common;

use common::{exchange, json, listening_addr, psao, start_role, stderr, Proc};
use psao_wire::{capabilities, encode_frame, Hello, Message, PROTOCOL_VERSION};

const TOKEN: &str = "sesame";

/// CesiumMan, or `None` (test skipped) without the shared data.
fn cesium_man() -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
        .join("characters/CesiumMan/CesiumMan.gltf");
    if p.exists() {
        Some(p.canonicalize().unwrap())
    } else {
        eprintln!("note: {} missing, test skipped", p.display());
        None
    }
}

/// A scene file in `dir` with a floor box and the character.
fn scene(dir: &Path, character: &Path) -> String {
    let file = dir.join("relit.toml");
    let text = format!(
        "[[asset]]\nfile = \"builtin:box\"\nscale = [4.0, 0.1, 4.0]\ntranslation = [0.0, -0.1, 0.0]\n\n\
         [[asset]]\nfile = {:?}\n",
        character.display().to_string()
    );
    std::fs::write(&file, text).unwrap();
    file.display().to_string()
}

/// `psao serve --relight` of `scene` with its models cached in `cache`.
fn serve(scene: &str, cache: &Path) -> (Proc, String) {
    let cache = cache.display().to_string();
    let server = [
        "--listen",
        "127.0.0.1:0",
        "--points",
        "48",
        "--ray-budget",
        "20000",
        "--token",
        TOKEN,
        "--points-cache",
        &cache,
        "--relight",
    ];
    let (child, line) = start_role("serve", scene, &server, &[]);
    (child, listening_addr(&line))
}

/// Status and body of `GET path` with the extra header lines.
fn get(addr: &str, path: &str, headers: &str) -> (u16, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let req = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n{headers}\r\n");
    s.write_all(req.as_bytes()).unwrap();
    let mut all = Vec::new();
    let _ = s.read_to_end(&mut all);
    let end = all.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&all[..end]);
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, all[end + 4..].to_vec())
}

/// The messages a client announcing `caps` receives before the server closes the session
/// (it closes its side right after the hello).
fn session(addr: &str, caps: u32) -> Vec<Message> {
    let hello = Message::Hello(Hello {
        version: PROTOCOL_VERSION,
        capabilities: caps,
        token: Some(TOKEN.into()),
        name: "test".into(),
    });
    exchange(
        addr,
        &encode_frame(&hello).unwrap(),
        Duration::from_secs(20),
    )
}

fn cached_models(cache: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(cache)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "prt"))
        .collect()
}

#[test]
fn served_characters_go_over_http_and_tcp_and_their_models_are_cached() {
    let Some(character) = cesium_man() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let scene = scene(dir.path(), &character);
    let (first, addr) = serve(&scene, &cache);
    let bearer = format!("Authorization: Bearer {TOKEN}\r\n");

    let (status, model) = get(&addr, "/characters/0.prt", &bearer);
    assert_eq!(status, 200);
    let read = psao_prt::model_file::from_bytes(&model).expect("a readable model");
    assert!(read.vertices > 1000, "{} vertices", read.vertices);
    assert_eq!(get(&addr, "/characters/0.prt", "").0, 401);
    assert_eq!(get(&addr, "/characters/1.prt", &bearer).0, 404);
    assert_eq!(get(&addr, "/characters/x.prt", &bearer).0, 404);

    let with = session(&addr, capabilities::ALL);
    assert!(
        matches!(with.first(), Some(Message::Welcome(_))),
        "{with:?}"
    );
    let relit: Vec<_> = with
        .iter()
        .filter_map(|m| match m {
            Message::Relighting(r) => Some(r),
            _ => None,
        })
        .collect();
    assert_eq!(relit.len(), 1);
    assert!(
        matches!(with[1], Message::Relighting(_)),
        "right after the welcome"
    );
    assert_eq!((relit[0].character, &relit[0].model), (0, &model));
    assert_eq!(relit[0].channels(), 3);
    let without = session(&addr, capabilities::ALL & !capabilities::RELIGHT);
    assert!(matches!(without.first(), Some(Message::Welcome(_))));
    assert!(!without.iter().any(|m| matches!(m, Message::Relighting(_))));
    drop(first);

    // The next start reads the stored model: the same file (not rewritten) and bytes.
    let stored = cached_models(&cache);
    assert_eq!(stored.len(), 1, "{stored:?}");
    let inode = std::fs::metadata(&stored[0]).unwrap().ino();
    let (_second, addr) = serve(&scene, &cache);
    assert_eq!(get(&addr, "/characters/0.prt", &bearer), (200, model));
    assert_eq!(cached_models(&cache), stored);
    assert_eq!(std::fs::metadata(&stored[0]).unwrap().ino(), inode);
}

/// A camera path in `dir` close to the character (the scene file places it at the floor's
/// edge, near x = −2).
fn close_path(dir: &Path) -> String {
    let file = dir.join("close.toml");
    let key = |t: f32, x: f32| {
        format!("[[key]]\ntime = {t}\nposition = [{x}, 1.2, 3.3]\nlook_at = [-2.0, 0.7, 0.6]\n\n")
    };
    let text = format!(
        "name = \"close\"\nfov_y_deg = 40.0\n\n{}{}",
        key(0.0, -1.0),
        key(1.0, -0.6)
    );
    std::fs::write(&file, text).unwrap();
    file.display().to_string()
}

/// The settings `psao serve` and `psao run` share in the view test (besides the cache).
const SHARED: [&str; 4] = ["--points", "48", "--ray-budget", "20000"];

#[test]
fn view_of_a_relit_serve_shows_the_frames_of_run_relight() {
    let Some(character) = cesium_man() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache").display().to_string();
    let scene = scene(dir.path(), &character);
    let out = |name: &str| dir.path().join(name).display().to_string();
    let path = close_path(dir.path());
    let frames = ["--res", "64x48", "--path", &path];
    let server = [
        &["--listen", "127.0.0.1:0", "--hz", "30", "--lockstep"][..],
        &["--wait-clients", "1", "--once", "--relight"],
        &["--points-cache", &cache],
        &SHARED,
    ]
    .concat();
    let (mut child, line) = start_role("serve", &scene, &server, &[]);
    let view_json = out("view.json");
    let o = psao(
        &[
            &[
                "view",
                "--connect",
                &listening_addr(&line),
                "--scene",
                &scene,
            ][..],
            &["--frames", "4", "--out", &out("view"), "--json", &view_json],
            &frames,
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(child.0.wait().unwrap().success());
    let run = |name: &str, relight: bool| {
        let dir = out(name);
        let mut args = [
            &[
                "run",
                "--scene",
                &scene,
                "--server-hz",
                "30",
                "--frames",
                "0..4",
            ][..],
            &["--points-cache", &cache, "--out", &dir],
            &frames,
            &SHARED,
        ]
        .concat();
        if relight {
            args.push("--relight");
        }
        let o = psao(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        json(&Path::new(&dir).join("stats.json"))
    };
    let relit = run("run", true);
    let view = json(Path::new(&view_json));
    assert_eq!(view["hash_mismatches"], 0, "{view}");
    assert_eq!(view["state_hash"], relit["state_hash"]);
    let png = |d: &str, name: &str| std::fs::read(dir.path().join(d).join(name)).unwrap();
    for f in 0..4 {
        for kind in ["frame", "ao"] {
            let name = format!("{kind}_{f:05}.png");
            assert!(png("run", &name) == png("view", &name), "{name}");
        }
    }
    // Relighting shows: the same run without it has other frames (and the same AO).
    let plain = run("plain", false);
    assert_eq!(plain["state_hash"], relit["state_hash"]);
    assert_eq!(png("plain", "ao_00003.png"), png("run", "ao_00003.png"));
    assert!(png("plain", "frame_00003.png") != png("run", "frame_00003.png"));
}
