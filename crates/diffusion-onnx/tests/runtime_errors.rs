//! A bad ONNX Runtime library is a clear error, not a panic or an abort. This file is its own test
//! process: ONNX Runtime can be loaded only once per process, so nothing else may load it first, and
//! nothing here loads a real one.

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

/// A truncated copy of the real library used to die with SIGBUS inside the dynamic loader (no
/// message at all); it is now refused before loading, naming the file and the cut.
#[test]
fn a_truncated_library_is_refused_before_it_can_crash_the_loader() {
    let real = diffusion_onnx::runtime::default_dylib_path();
    let bytes = std::fs::read(&real)
        .unwrap_or_else(|e| panic!("{}: {e}; run scripts/setup-onnxruntime.sh", real.display()));
    let dir = tempfile::tempdir().expect("tempdir");
    let cut = dir.path().join("libonnxruntime.so.1.31.1");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).expect("write");
    let msg = match environment_from(&cut) {
        Ok(_) => panic!("a truncated library was loaded"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains("truncated")
            && msg.contains(&cut.display().to_string())
            && msg.contains("setup-onnxruntime.sh"),
        "{msg}"
    );
}

/// A stand-in library with ONNX Runtime's entry point that reports version 1.10.0 (and would hand out
/// no API table): the "too old" case, which ort checks before touching the API.
const OLD_ORT_C: &str = r#"
typedef struct { const void *(*GetApi)(unsigned); const char *(*GetVersionString)(void); } OrtApiBase;
static const void *get_api(unsigned v) { (void)v; return 0; }
static const char *version(void) { return "1.10.0"; }
static const OrtApiBase base = { get_api, version };
const OrtApiBase *OrtGetApiBase(void) { return &base; }
"#;

#[test]
fn a_too_old_runtime_is_refused_with_the_version_and_instructions() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = dir.path().join("old_ort.c");
    let lib = dir.path().join("libonnxruntime.so.1.10.0");
    std::fs::write(&src, OLD_ORT_C).expect("write C source");
    // gcc/cc is on every machine that builds this workspace (the `onig` dependency compiles C).
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".to_string());
    let status = std::process::Command::new(&cc)
        .args(["-shared", "-fPIC", "-o"])
        .arg(&lib)
        .arg(&src)
        .status()
        .unwrap_or_else(|e| panic!("running the C compiler `{cc}` failed: {e}"));
    assert!(status.success(), "compiling the stand-in library failed");
    let msg = match environment_from(&lib) {
        Ok(_) => panic!("ONNX Runtime 1.10 was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains("1.10.0") && msg.contains(">= 1.30") && msg.contains("setup-onnxruntime.sh"),
        "{msg}"
    );
}
