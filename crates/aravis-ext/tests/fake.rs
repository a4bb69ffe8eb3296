//! The fake camera streams what its fill closure draws, to a camera opened by address.

use aravis::prelude::*;
use aravis_ext::{FakeCamera, FakeCameraConfig, Interface, aravis, open_gv_camera, use_only_interfaces};

#[test]
fn fake_camera_streams_what_the_closure_draws() {
    use_only_interfaces(&[]);
    let fill = Box::new(|frame: &mut [u8], width: u32, _height: u32, frame_id: u64| {
        for (i, byte) in frame.iter_mut().enumerate() {
            *byte = ((i % width as usize) as u64 + frame_id) as u8;
        }
    });
    let fake = FakeCamera::start(&FakeCameraConfig::default(), fill).unwrap();
    let camera = open_gv_camera(fake.address()).unwrap();
    assert_eq!(camera.device_serial_number().unwrap().as_str(), "GV01");
    camera.set_region(0, 0, 64, 32).unwrap();
    camera.set_frame_rate(100.0).unwrap();
    let payload = camera.payload().unwrap() as usize;
    assert_eq!(payload, 64 * 32);
    let stream = camera.create_stream().unwrap();
    for _ in 0..4 {
        stream.push_buffer(aravis::Buffer::new_allocate(payload));
    }
    camera.start_acquisition().unwrap();
    let mut got = 0;
    for _ in 0..50 {
        let Some(buffer) = stream.timeout_pop_buffer(1_000_000) else {
            continue;
        };
        if buffer.status() == aravis::BufferStatus::Success {
            let data = buffer.image_data();
            let id = buffer.frame_id();
            assert_eq!(data.len(), payload);
            assert_eq!(data[5], (5 + id) as u8);
            got += 1;
        }
        stream.push_buffer(buffer);
        if got == 5 {
            break;
        }
    }
    camera.stop_acquisition().unwrap();
    assert_eq!(got, 5);
    let _ = Interface::ALL;
}
