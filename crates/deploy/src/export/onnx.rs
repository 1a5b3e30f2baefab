//! The policy as an ONNX graph (opset 13): raw observations in, the deterministic action and
//! the environment's action out. See docs/export.md for the graph.
//!
//! The protobuf messages come from `onnx-protobuf` (types pregenerated from onnx.proto, so no
//! `protoc` is needed to build); only the graph's layout is written here.

use crate::export::spec::{Head, PolicySpec};
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
    let features = match &spec.normalization {
        Some(n) => {
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
        None => INPUT.to_string(),
    };
    let mut x = features;
    for (i, layer) in spec.layers.iter().enumerate() {
        let weight = format!("{}.weight", layer.name);
        let bias = format!("{}.bias", layer.name);
        builder.f32_constant(&weight, &[layer.outputs, layer.inputs], &layer.weight);
        builder.f32_constant(&bias, &[layer.outputs], &layer.bias);
        let mut gemm = node("Gemm", &[&x, &weight, &bias], &builder.fresh());
        gemm.attribute.push(int_attribute("transB", 1));
        x = builder.push(gemm);
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
        input: vec![tensor_value(
            INPUT,
            DataType::FLOAT,
            spec.obs_dim as i64,
            "raw observations, one per row (normalisation is in the graph)",
        )],
        output: vec![
            tensor_value(
                OUTPUT_ACTION,
                DataType::FLOAT,
                act_dim,
                "deterministic policy action, unclipped (Policy::act(obs, true))",
            ),
            tensor_value(
                OUTPUT_ENV_ACTION,
                DataType::FLOAT,
                act_dim,
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

/// A `batch × width` tensor of `elem`, the batch size left free.
fn tensor_value(name: &str, elem: DataType, width: i64, doc: &str) -> ValueInfoProto {
    let dims = [
        dimension::Value::DimParam("batch".into()),
        dimension::Value::DimValue(width),
    ];
    let shape = TensorShapeProto {
        dim: dims
            .into_iter()
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
