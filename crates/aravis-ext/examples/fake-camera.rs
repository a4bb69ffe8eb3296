//! Aravis's fake GigE Vision camera on 127.0.0.1, as `arv-fake-gv-camera-0.8` runs it, with the
//! rate at which it answers a software trigger set (that program leaves Aravis's 25 Hz, so a
//! triggered frame waits up to 40 ms). Frames are a ramp shifted by the frame id. Runs until
//! killed.
//!
//!   cargo run --release -p aravis-ext --example fake-camera -- [--serial S] [--trigger-frequency HZ]

use aravis_ext::{FakeCamera, FakeCameraConfig, use_only_interfaces};

fn main() {
    let mut config = FakeCameraConfig::default();
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let value = args.next();
        match (arg.as_str(), value) {
            ("--serial", Some(serial)) => config.serial = serial,
            ("--trigger-frequency", Some(hz)) => match hz.parse::<f64>() {
                Ok(hz) if hz.is_finite() && hz > 0.0 => config.trigger_frequency = Some(hz),
                _ => fail(&format!(
                    "--trigger-frequency must be a number of Hz above 0, not {hz:?}"
                )),
            },
            (other, _) => fail(&format!(
                "unknown argument {other:?} (usage: fake-camera [--serial S] [--trigger-frequency HZ])"
            )),
        }
    }
    use_only_interfaces(&[]);
    let fill = Box::new(|frame: &mut [u8], width: u32, _height: u32, frame_id: u64| {
        let width = width.max(1) as usize;
        for (i, byte) in frame.iter_mut().enumerate() {
            *byte = ((frame_id as usize * 7 + i % width + 3 * (i / width)) % 251) as u8;
        }
    });
    let _camera = match FakeCamera::start(&config, fill) {
        Ok(camera) => camera,
        Err(error) => fail(&format!("the fake camera did not start: {error}")),
    };
    loop {
        std::thread::park();
    }
}

fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(2);
}
