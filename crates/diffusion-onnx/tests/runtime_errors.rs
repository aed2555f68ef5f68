//! A bad ONNX Runtime library is a clear error, not a panic or an abort. This file is its own test
//! process: ONNX Runtime can be loaded only once per process, so nothing else may load it first.

use diffusion_onnx::runtime::environment_from;

#[test]
fn a_file_that_is_not_a_library_is_refused_with_instructions() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fake = dir.path().join("libonnxruntime.so.1.31.1");
    std::fs::write(&fake, b"this is not an ELF shared object").expect("write");
    let msg = match environment_from(&fake) {
        Ok(_) => panic!("a text file was accepted as ONNX Runtime"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains("cannot be used")
            && msg.contains("setup-onnxruntime.sh")
            && msg.contains("ORT_DYLIB_PATH"),
        "{msg}"
    );
    assert!(msg.contains(&fake.display().to_string()), "{msg}");
}
