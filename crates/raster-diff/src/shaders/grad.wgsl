// Gradient accumulation shared by the backward passes (prefixed with common.wgsl).
// WGSL has no float atomics: each add is a compare-exchange loop on the f32 bit pattern, so the
// order of the adds — hence the f32 rounding of the sums — depends on scheduling.

@group(0) @binding(10) var<storage, read_write> grad: array<atomic<u32>>;

fn atomic_add_grad(i: u32, value: f32) {
    if (value == 0.0) {
        return;
    }
    var old = atomicLoad(&grad[i]);
    loop {
        let new_bits = bitcast<u32>(bitcast<f32>(old) + value);
        let r = atomicCompareExchangeWeak(&grad[i], old, new_bits);
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}

fn add_grad3(i: u32, value: vec3<f32>) {
    atomic_add_grad(3u * i, value.x);
    atomic_add_grad(3u * i + 1u, value.y);
    atomic_add_grad(3u * i + 2u, value.z);
}
