//! The viewer end to end: a server on an ephemeral port, spoken to over a real socket.

use super::{ViewArgs, Viewer, start};
use serde_json::Value;
use std::io::{Read, Write};
use std::net::TcpStream;

fn viewer() -> Viewer {
    viewer_of(None)
}

fn viewer_of(twin: Option<String>) -> Viewer {
    let args = ViewArgs {
        id: None,
        model: None,
        port: 0,
        bind: "127.0.0.1".parse().unwrap(),
        width: 160,
        height: 120,
        seed: 0,
        overrides: Vec::new(),
        twin,
    };
    start(&args).expect("the viewer starts").0
}

/// One HTTP/1.0 exchange: (status, body).
fn http(viewer: &Viewer, method: &str, path: &str, body: &str) -> (u16, Vec<u8>) {
    let mut stream = TcpStream::connect(viewer.addr).unwrap();
    write!(
        stream,
        "{method} {path} HTTP/1.0\r\nHost: localhost\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut reply = Vec::new();
    stream.read_to_end(&mut reply).unwrap();
    let split = reply
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a header");
    let head = String::from_utf8_lossy(&reply[..split]);
    let status = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (status, reply[split + 4..].to_vec())
}

fn state(viewer: &Viewer) -> Value {
    let (status, body) = http(viewer, "GET", "/state", "");
    assert_eq!(status, 200);
    serde_json::from_slice(&body).unwrap()
}

fn control(viewer: &Viewer, command: &str) -> (u16, String) {
    let (status, body) = http(viewer, "POST", "/control", command);
    (status, String::from_utf8_lossy(&body).into_owned())
}

/// The frame's RGB bytes, checked to be a PNG of the configured size.
fn frame(viewer: &Viewer) -> Vec<u8> {
    frame_from(viewer, "az=-40&el=20&dist=1.6")
}

fn frame_from(viewer: &Viewer, camera: &str) -> Vec<u8> {
    let (status, body) = http(viewer, "GET", &format!("/frame.png?{camera}"), "");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let decoder = png::Decoder::new(std::io::Cursor::new(body));
    let mut reader = decoder.read_info().unwrap();
    let mut rgb = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut rgb).unwrap();
    assert_eq!((info.width, info.height), (160, 120));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    rgb.truncate(info.buffer_size());
    rgb
}

fn changed_pixels(a: &[u8], b: &[u8]) -> usize {
    a.chunks(3).zip(b.chunks(3)).filter(|(p, q)| p != q).count()
}

#[test]
fn frames_state_step_and_bad_requests() {
    let viewer = viewer();
    let (status, page) = http(&viewer, "GET", "/", "");
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("viewer.js"));

    let first = frame(&viewer);
    let colours: std::collections::HashSet<&[u8]> = first.chunks(3).collect();
    assert!(colours.len() > 10, "the frame is (nearly) one colour");

    // The orbit camera: another azimuth and a nearer camera see another picture.
    let turned = frame_from(&viewer, "az=60&el=20&dist=1.6");
    assert!(
        changed_pixels(&first, &turned) > 2000,
        "the azimuth changed little: {}",
        changed_pixels(&first, &turned)
    );
    let nearer = frame_from(&viewer, "az=-40&el=20&dist=0.8");
    assert!(
        changed_pixels(&first, &nearer) > 2000,
        "the distance changed little: {}",
        changed_pixels(&first, &nearer)
    );

    let before = state(&viewer);
    assert_eq!(before["step"], 0);
    assert_eq!(control(&viewer, r#"{"cmd":"step"}"#).0, 200);
    for _ in 0..4 {
        control(&viewer, r#"{"cmd":"step"}"#);
    }
    let after = state(&viewer);
    assert_eq!(after["step"], 5);
    assert!(after["reward_terms"].is_object());
    assert!(
        changed_pixels(&first, &frame(&viewer)) > 0,
        "five random steps moved nothing"
    );

    for bad in [
        "not json",
        r#"{"cmd":"fly"}"#,
        r#"{"cmd":"joints","degrees":[NaN,0,0,0,0,0]}"#,
        r#"{"cmd":"mode","mode":"policy"}"#,
        r#"{"cmd":"joints","degrees":[0,0,0,0,0,0]}"#,
    ] {
        let (status, message) = control(&viewer, bad);
        assert_eq!(status, 400, "{bad} → {message}");
        assert!(!message.is_empty());
    }
    assert_eq!(control(&viewer, r#"{"cmd":"mode","mode":"manual"}"#).0, 200);
    let (status, message) = control(&viewer, r#"{"cmd":"joints","degrees":[1,2]}"#);
    assert_eq!(status, 400);
    assert!(message.contains("expected 6"), "{message}");
    for query in ["az=abc", "el=120", "dist=-1", "tx=inf"] {
        let (status, _) = http(&viewer, "GET", &format!("/frame.png?{query}"), "");
        assert_eq!(status, 400, "{query}");
    }
    assert_eq!(http(&viewer, "GET", "/nothing", "").0, 404);
    assert_eq!(http(&viewer, "DELETE", "/state", "").0, 405);
    viewer.stop();
}

#[test]
fn manual_joints_move_the_arm_in_the_next_frame() {
    let viewer = viewer();
    assert_eq!(control(&viewer, r#"{"cmd":"mode","mode":"manual"}"#).0, 200);
    let before = frame(&viewer);
    let s = state(&viewer);
    let mut degrees: Vec<f64> = s["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["degrees"].as_f64().unwrap())
        .collect();
    let start = degrees[0];
    degrees[0] += 30.0;
    let command = serde_json::json!({"cmd": "joints", "degrees": degrees}).to_string();
    let (status, message) = control(&viewer, &command);
    assert_eq!(status, 200, "{message}");
    let moved = state(&viewer)["joints"][0]["degrees"].as_f64().unwrap();
    assert!(moved - start > 20.0, "joint 1 went from {start} to {moved}");
    let after = frame(&viewer);
    // The arm swinging 30° about its base repaints a good part of a 160×120 frame.
    let changed = changed_pixels(&before, &after);
    assert!(changed > 300, "only {changed} pixels changed");
    viewer.stop();
}

#[test]
fn twin_mode_shows_the_twins_arm() {
    use fairgrasp_deploy::twin::{Twin, TwinConfig};
    let twin = Twin::spawn(TwinConfig::ephemeral()).unwrap();
    let addr = twin.cnde_addr().to_string();
    let viewer = viewer_of(Some(addr.clone()));
    let s = state(&viewer);
    assert_eq!(s["mode"], "twin");
    assert_eq!(s["twin"], addr.as_str());
    assert_eq!(s["joints"].as_array().unwrap().len(), 6);
    let rgb = frame(&viewer);
    let colours: std::collections::HashSet<&[u8]> = rgb.chunks(3).collect();
    assert!(
        colours.len() > 10,
        "the twin's frame is (nearly) one colour"
    );
    // Stepping follows the twin rather than the simulation.
    assert_eq!(control(&viewer, r#"{"cmd":"step"}"#).0, 200);
    assert_eq!(state(&viewer)["total_steps"], 0);
    viewer.stop();
}
