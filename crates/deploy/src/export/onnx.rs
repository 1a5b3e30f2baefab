//! The policy as an ONNX graph (opset 13): raw observations in (a camera policy: the state and
//! each camera's image), the deterministic action and the environment's action out. See
//! docs/export.md for the graph.
//!
//! The protobuf messages come from `onnx-protobuf` (types pregenerated from onnx.proto, so no
//! `protoc` is needed to build); only the graph's layout is written here.

use crate::export::spec::{CameraInputs, Conv, Dense, Head, PolicySpec};
use fairgrasp_rl::nn::Activation;
use onnx_protobuf::attribute_proto::AttributeType;
use onnx_protobuf::tensor_proto::DataType;
use onnx_protobuf::tensor_shape_proto::{Dimension, dimension};
use onnx_protobuf::{
    AttributeProto, GraphProto, Message, ModelProto, NodeProto, OperatorSetIdProto,
    StringStringEntryProto, TensorProto, TensorShapeProto, TypeProto, ValueInfoProto, type_proto,
};
use protobuf::{EnumOrUnknown, MessageField};

/// The operator set the graph uses; every runtime of the last years runs it.
pub const OPSET: i64 = 13;
/// The IR version that goes with [`OPSET`] (ONNX 1.8).
const IR_VERSION: i64 = 7;
/// The graph's input: raw observations, `batch × obs_dim` float32.
pub const INPUT: &str = "observation";
/// A camera policy's state input (`batch × obs_dim` float32) beside one `u8` input per camera
/// named as the camera's image (`scene_rgb`: `batch × height × width × channels`): the keys of
/// the environment's Gymnasium `Dict` observation.
pub const STATE_INPUT: &str = "state";
/// The deterministic action, unclipped: what `Policy::act(obs, true)` returns.
pub const OUTPUT_ACTION: &str = "action";
/// The action as the environment receives it: clipped to `[-1, 1]`, then mapped onto the
/// environment's action box.
pub const OUTPUT_ENV_ACTION: &str = "env_action";

/// The serialised ONNX model of `spec`.
pub fn onnx_bytes(spec: &PolicySpec) -> Result<Vec<u8>, String> {
    model(spec)
        .write_to_bytes()
        .map_err(|e| format!("cannot encode the ONNX model: {e}"))
}

/// The ONNX model of `spec`, with its metadata (see [`metadata`]).
pub fn model(spec: &PolicySpec) -> ModelProto {
    let mut builder = Builder::default();
    let features = match (&spec.camera, &spec.normalization) {
        (Some(camera), _) => camera_features(&mut builder, camera),
        (None, Some(n)) => {
            // In f64, so the result is bit for bit that of `VecNormalizeState::normalize_obs`.
            let obs = builder.cast(INPUT, DataType::DOUBLE);
            builder.f64_constant("obs_norm.mean", &[spec.obs_dim], &n.mean);
            builder.f64_constant("obs_norm.scale", &[spec.obs_dim], &n.scale());
            builder.f64_constant("obs_norm.clip_low", &[], &[-n.clip]);
            builder.f64_constant("obs_norm.clip_high", &[], &[n.clip]);
            let centred = builder.op("Sub", &[&obs, "obs_norm.mean"]);
            let scaled = builder.op("Div", &[&centred, "obs_norm.scale"]);
            let clipped = builder.clamp(&scaled, "obs_norm.clip_low", "obs_norm.clip_high");
            builder.cast(&clipped, DataType::FLOAT)
        }
        (None, None) => INPUT.to_string(),
    };
    let mut x = features;
    for (i, layer) in spec.layers.iter().enumerate() {
        x = builder.dense(&x, layer);
        if i + 1 < spec.layers.len() {
            x = match spec.activation {
                Activation::Tanh => builder.op("Tanh", &[&x]),
                Activation::Relu => builder.op("Relu", &[&x]),
            };
        }
    }
    let head = match spec.head {
        Head::Mean => "Identity",
        Head::TanhMean => "Tanh",
    };
    builder.push(node(head, &[&x], OUTPUT_ACTION));
    env_action(&mut builder, spec);

    let act_dim = spec.act_dim as i64;
    let graph = GraphProto {
        name: "fairgrasp_policy".into(),
        node: builder.nodes,
        initializer: builder.constants,
        input: inputs(spec),
        output: vec![
            tensor_value(
                OUTPUT_ACTION,
                DataType::FLOAT,
                &[act_dim],
                "deterministic policy action, unclipped (Policy::act(obs, true))",
            ),
            tensor_value(
                OUTPUT_ENV_ACTION,
                DataType::FLOAT,
                &[act_dim],
                "the action the environment receives: clipped to [-1, 1], mapped onto its action box",
            ),
        ],
        doc_string: format!(
            "{} policy for {}: `{OUTPUT_ENV_ACTION}` is what the environment's step takes",
            spec.algo, spec.env_id
        ),
        ..Default::default()
    };
    ModelProto {
        ir_version: IR_VERSION,
        opset_import: vec![OperatorSetIdProto {
            domain: String::new(),
            version: OPSET,
            ..Default::default()
        }],
        producer_name: "fairgrasp".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        doc_string: "A fairgrasp policy: raw observation in, deterministic action out".into(),
        graph: MessageField::some(graph),
        metadata_props: metadata(spec)
            .into_iter()
            .map(|(key, value)| StringStringEntryProto {
                key,
                value,
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    }
}

/// The graph's inputs: the observation vector, or a camera policy's state and images.
fn inputs(spec: &PolicySpec) -> Vec<ValueInfoProto> {
    let Some(camera) = &spec.camera else {
        return vec![tensor_value(
            INPUT,
            DataType::FLOAT,
            &[spec.obs_dim as i64],
            "raw observations, one per row (normalisation is in the graph)",
        )];
    };
    let mut inputs = vec![tensor_value(
        STATE_INPUT,
        DataType::FLOAT,
        &[spec.obs_dim as i64],
        "the arm's readings, one observation per row (standardised in the graph)",
    )];
    for e in &camera.encoders {
        let v = &e.view;
        inputs.push(tensor_value(
            &v.name,
            DataType::UINT8,
            &[v.height as i64, v.width as i64, v.channels as i64],
            "the camera's image, height × width × channels, as the environment renders it",
        ));
    }
    inputs
}

/// A camera policy's head input: each camera's features (its `u8` image to [0, 1], channel-first
/// for ONNX's `Conv`, the convolutions with ReLU, back to channel-last, flattened, the dense
/// layer with ReLU), then the standardised state.
fn camera_features(builder: &mut Builder, camera: &CameraInputs) -> String {
    builder.f32_constant("pixel.scale", &[], &[255.0]);
    let mut parts = Vec::new();
    for e in &camera.encoders {
        let pixels = builder.cast(&e.view.name, DataType::FLOAT);
        let unit = builder.op("Div", &[&pixels, "pixel.scale"]);
        let mut x = builder.transpose(&unit, &[0, 3, 1, 2]);
        for c in &e.convs {
            let (weight, bias) = (format!("{}.weight", c.name), format!("{}.bias", c.name));
            let dims = [c.filters, c.channels, c.kernel, c.kernel];
            builder.f32_constant(&weight, &dims, &channel_first(c));
            builder.f32_constant(&bias, &[c.filters], &c.bias);
            let mut conv = node("Conv", &[&x, &weight, &bias], &builder.fresh());
            conv.attribute
                .push(ints_attribute("kernel_shape", &[c.kernel, c.kernel]));
            conv.attribute
                .push(ints_attribute("strides", &[c.stride, c.stride]));
            x = builder.push(conv);
            x = builder.op("Relu", &[&x]);
        }
        let last = builder.transpose(&x, &[0, 2, 3, 1]);
        let mut flatten = node("Flatten", &[&last], &builder.fresh());
        flatten.attribute.push(int_attribute("axis", 1));
        let flat = builder.push(flatten);
        let features = builder.dense(&flat, &e.fc);
        parts.push(builder.op("Relu", &[&features]));
    }
    let n = camera.state_mean.len();
    builder.f32_constant("state.mean", &[n], &camera.state_mean);
    builder.f32_constant("state.std", &[n], &camera.state_std);
    let centred = builder.op("Sub", &[STATE_INPUT, "state.mean"]);
    parts.push(builder.op("Div", &[&centred, "state.std"]));
    let refs: Vec<&str> = parts.iter().map(String::as_str).collect();
    let mut concat = node("Concat", &refs, &builder.fresh());
    concat.attribute.push(int_attribute("axis", 1));
    builder.push(concat)
}

/// A convolution's filters as ONNX lays them out: `filters × channels × kernel × kernel`.
fn channel_first(c: &Conv) -> Vec<f32> {
    let k = c.kernel;
    let mut out = vec![0.0; c.weight.len()];
    for f in 0..c.filters {
        for y in 0..k {
            for x in 0..k {
                for ch in 0..c.channels {
                    out[((f * c.channels + ch) * k + y) * k + x] =
                        c.weight[((f * k + y) * k + x) * c.channels + ch];
                }
            }
        }
    }
    out
}

/// The model's metadata properties: `env_id`, `env_config` (JSON), `algo`, `obs_dim`,
/// `act_dim`, `action_layout`, `action_low` and `action_high` (the environment's box, JSON
/// arrays), `normalized` (`true` when the graph normalises the observation), `num_timesteps`.
pub fn metadata(spec: &PolicySpec) -> Vec<(String, String)> {
    let json = |v: &[f32]| serde_json::to_string(v).expect("numbers serialise");
    [
        ("env_id", spec.env_id.clone()),
        ("env_config", spec.env_config.to_string()),
        ("algo", spec.algo.clone()),
        ("obs_dim", spec.obs_dim.to_string()),
        ("act_dim", spec.act_dim.to_string()),
        ("action_layout", spec.action_layout.clone()),
        ("action_low", json(&spec.env_action.low)),
        ("action_high", json(&spec.env_action.high)),
        ("normalized", spec.normalization.is_some().to_string()),
        ("num_timesteps", spec.num_timesteps.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// `env_action = clamp(lerp(low, high, clamp(action, ±1)), low, high)`, in the same f64
/// arithmetic as `RescaleAction::to_inner_action`: `0.5(1 − a)·low + 0.5(1 + a)·high`.
fn env_action(builder: &mut Builder, spec: &PolicySpec) {
    let n = spec.act_dim;
    let (low, high) = (&spec.env_action.low, &spec.env_action.high);
    builder.f32_constant("unit.low", &[], &[-1.0]);
    builder.f32_constant("unit.high", &[], &[1.0]);
    builder.f64_constant("one", &[], &[1.0]);
    let half = |v: &[f32]| v.iter().map(|&x| 0.5 * x as f64).collect::<Vec<f64>>();
    builder.f64_constant("env_action.half_low", &[n], &half(low));
    builder.f64_constant("env_action.half_high", &[n], &half(high));
    builder.f32_constant("env_action.low", &[n], low);
    builder.f32_constant("env_action.high", &[n], high);
    let unit = builder.clamp(OUTPUT_ACTION, "unit.low", "unit.high");
    let a = builder.cast(&unit, DataType::DOUBLE);
    let below = builder.op("Sub", &["one", &a]);
    let above = builder.op("Add", &["one", &a]);
    let from_low = builder.op("Mul", &[&below, "env_action.half_low"]);
    let from_high = builder.op("Mul", &[&above, "env_action.half_high"]);
    let sum = builder.op("Add", &[&from_low, &from_high]);
    let single = builder.cast(&sum, DataType::FLOAT);
    let floor = builder.op("Max", &[&single, "env_action.low"]);
    builder.push(node("Min", &[&floor, "env_action.high"], OUTPUT_ENV_ACTION));
}

/// Nodes and constants, in order, with fresh names for intermediate values.
#[derive(Default)]
struct Builder {
    nodes: Vec<NodeProto>,
    constants: Vec<TensorProto>,
    count: usize,
}

impl Builder {
    fn fresh(&mut self) -> String {
        self.count += 1;
        format!("t{}", self.count)
    }

    /// Adds `node`; returns its (single) output's name.
    fn push(&mut self, mut node: NodeProto) -> String {
        node.name = format!("n{}_{}", self.nodes.len(), node.op_type);
        let out = node.output[0].clone();
        self.nodes.push(node);
        out
    }

    fn op(&mut self, op: &str, inputs: &[&str]) -> String {
        let out = self.fresh();
        self.push(node(op, inputs, &out))
    }

    /// `x Wᵀ + b` (a `Gemm`), its weight and bias added as constants.
    fn dense(&mut self, x: &str, layer: &Dense) -> String {
        let weight = format!("{}.weight", layer.name);
        let bias = format!("{}.bias", layer.name);
        self.f32_constant(&weight, &[layer.outputs, layer.inputs], &layer.weight);
        self.f32_constant(&bias, &[layer.outputs], &layer.bias);
        let mut gemm = node("Gemm", &[x, &weight, &bias], &self.fresh());
        gemm.attribute.push(int_attribute("transB", 1));
        self.push(gemm)
    }

    fn transpose(&mut self, input: &str, perm: &[usize]) -> String {
        let mut t = node("Transpose", &[input], &self.fresh());
        t.attribute.push(ints_attribute("perm", perm));
        self.push(t)
    }

    fn cast(&mut self, input: &str, to: DataType) -> String {
        let mut cast = node("Cast", &[input], &self.fresh());
        cast.attribute.push(int_attribute("to", to as i64));
        self.push(cast)
    }

    /// `min(max(x, low), high)`: bounds of any shape that broadcasts (Clip takes scalars only).
    fn clamp(&mut self, x: &str, low: &str, high: &str) -> String {
        let floor = self.op("Max", &[x, low]);
        self.op("Min", &[&floor, high])
    }

    fn f32_constant(&mut self, name: &str, dims: &[usize], values: &[f32]) {
        self.constants.push(TensorProto {
            name: name.into(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: DataType::FLOAT as i32,
            float_data: values.to_vec(),
            ..Default::default()
        });
    }

    fn f64_constant(&mut self, name: &str, dims: &[usize], values: &[f64]) {
        self.constants.push(TensorProto {
            name: name.into(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: DataType::DOUBLE as i32,
            double_data: values.to_vec(),
            ..Default::default()
        });
    }
}

fn node(op: &str, inputs: &[&str], output: &str) -> NodeProto {
    NodeProto {
        op_type: op.into(),
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: vec![output.into()],
        ..Default::default()
    }
}

fn int_attribute(name: &str, value: i64) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        type_: EnumOrUnknown::new(AttributeType::INT),
        i: value,
        ..Default::default()
    }
}

fn ints_attribute(name: &str, values: &[usize]) -> AttributeProto {
    AttributeProto {
        name: name.into(),
        type_: EnumOrUnknown::new(AttributeType::INTS),
        ints: values.iter().map(|&v| v as i64).collect(),
        ..Default::default()
    }
}

/// A `batch × dims…` tensor of `elem`, the batch size left free.
fn tensor_value(name: &str, elem: DataType, dims: &[i64], doc: &str) -> ValueInfoProto {
    let dims = std::iter::once(dimension::Value::DimParam("batch".into()))
        .chain(dims.iter().map(|&d| dimension::Value::DimValue(d)));
    let shape = TensorShapeProto {
        dim: dims
            .map(|value| Dimension {
                value: Some(value),
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    };
    ValueInfoProto {
        name: name.into(),
        doc_string: doc.into(),
        type_: MessageField::some(TypeProto {
            value: Some(type_proto::Value::TensorType(type_proto::Tensor {
                elem_type: elem as i32,
                shape: MessageField::some(shape),
                ..Default::default()
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}
