#!/usr/bin/env python3
"""Pass-through "UNets" with IF's stage signatures and real 77 x 4096 text embeddings: the output is
the sample (ONNX Identity), so timing a call measures the session boundary (copies, allocations,
IO binding) without the network's arithmetic (docs/benchmarks.md, "IO binding").

    python scripts/make_passthrough_unet.py OUT_DIR     # writes OUT_DIR/pass-fp32, OUT_DIR/pass-fp16

Needs only the `onnx` package (in scripts/requirements-export.txt).
"""
import onnx
from onnx import TensorProto, helper

def model(cin, labels, dtype):
    t = TensorProto.FLOAT if dtype == "fp32" else TensorProto.FLOAT16
    ins = [helper.make_tensor_value_info("sample", t, ["N", cin, "H", "W"]),
           helper.make_tensor_value_info("timestep", TensorProto.INT64, ["N"]),
           helper.make_tensor_value_info("encoder_hidden_states", t, ["N", 77, 4096])]
    if labels:
        ins.append(helper.make_tensor_value_info("class_labels", TensorProto.INT64, ["N"]))
    out = helper.make_tensor_value_info("noise_pred", t, ["N", cin, "H", "W"])
    g = helper.make_graph([helper.make_node("Identity", ["sample"], ["noise_pred"])], "pass", ins, [out])
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 18)])
    m.ir_version = 9
    return m

import os, sys
if len(sys.argv) != 2:
    sys.exit(__doc__)
for dtype in ["fp32", "fp16"]:
    d = os.path.join(sys.argv[1], f"pass-{dtype}")
    os.makedirs(d, exist_ok=True)
    onnx.save(model(3, False, dtype), f"{d}/unet_stage1.onnx")
    onnx.save(model(6, True, dtype), f"{d}/unet_stage2.onnx")
    sched = '''name = "DDPMScheduler"
num_train_timesteps = 1000
beta_schedule = "squaredcos_cap_v2"
variance_type = "learned_range"
prediction_type = "epsilon"
'''
    common = f'''external_data = []
dtype = "{dtype}"
sample = "sample"
timestep = "timestep"
encoder_hidden_states = "encoder_hidden_states"
output = "noise_pred"
'''
    open(f"{d}/manifest.toml", "w").write(f'''format_version = 1
name = "passthrough-{dtype}"

[embeddings]
dim = 4096
tokens = 77
uncond = "builtin:if-t5-v1_1-xxl-empty"

[stage1]
file = "unet_stage1.onnx"
in_channels = 3
out_channels = 3
sample_size = 64
{common}
[stage1.scheduler]
{sched}
[stage2]
file = "unet_stage2.onnx"
in_channels = 6
out_channels = 6
sample_size = 256
class_labels = "class_labels"
{common}
[stage2.scheduler]
{sched}
[stage2.noising_scheduler]
{sched}''')
