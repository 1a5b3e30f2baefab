//! XML-RPC values, faults, and the XML of calls and responses (through `dxr`).

use std::fmt;

/// An XML-RPC value of the kinds the FAIRINO interface uses. `Nil` is the common
/// `<nil/>` extension (Python sends it for `None`).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `<int>` or `<i4>`.
    Int(i32),
    /// `<double>`.
    Double(f64),
    /// `<boolean>`.
    Bool(bool),
    /// `<string>`, or bare text in `<value>`.
    String(String),
    /// `<array>`.
    Array(Vec<Value>),
    /// `<nil/>`.
    Nil,
}

impl Value {
    /// An array of doubles, as the controller takes joint and pose vectors.
    pub fn doubles(values: &[f64]) -> Value {
        Value::Array(values.iter().map(|&v| Value::Double(v)).collect())
    }

    /// The number in an `Int` or a `Double`.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Int(i) => Some(f64::from(*i)),
            Value::Double(d) => Some(*d),
            _ => None,
        }
    }

    /// The integer in an `Int`.
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(i64::from(*i)),
            _ => None,
        }
    }

    /// The integer in an `Int`.
    pub fn as_i32(&self) -> Option<i32> {
        match self {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }

    /// The truth value in a `Bool`.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }

    /// The text in a `String`.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(s) => Some(s),
            _ => None,
        }
    }

    /// The items of an `Array`.
    pub fn as_array(&self) -> Option<&[Value]> {
        match self {
            Value::Array(items) => Some(items),
            _ => None,
        }
    }

    /// The XML-RPC type name, for messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Int(_) => "int",
            Value::Double(_) => "double",
            Value::Bool(_) => "boolean",
            Value::String(_) => "string",
            Value::Array(_) => "array",
            Value::Nil => "nil",
        }
    }
}

impl From<i32> for Value {
    fn from(v: i32) -> Self {
        Value::Int(v)
    }
}

impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Double(v)
    }
}

impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Value::Bool(v)
    }
}

impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::String(v.to_string())
    }
}

impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::String(v)
    }
}

impl From<Vec<Value>> for Value {
    fn from(v: Vec<Value>) -> Self {
        Value::Array(v)
    }
}

/// An XML-RPC fault: the server's way of saying a call failed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Fault {
    /// `faultCode`.
    pub code: i32,
    /// `faultString`.
    pub message: String,
}

impl Fault {
    /// A fault with its code and text.
    pub fn new(code: i32, message: impl Into<String>) -> Self {
        Self {
            code,
            message: message.into(),
        }
    }
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "XML-RPC fault {}: {}", self.code, self.message)
    }
}

impl std::error::Error for Fault {}

fn to_dxr(value: &Value) -> dxr::Value {
    match value {
        Value::Int(i) => dxr::Value::Integer(*i),
        Value::Double(d) => dxr::Value::Double(*d),
        Value::Bool(b) => dxr::Value::Boolean(*b),
        Value::String(s) => dxr::Value::String(s.clone()),
        Value::Array(items) => dxr::Value::Array(items.iter().map(to_dxr).collect()),
        Value::Nil => dxr::Value::Nil,
    }
}

fn from_dxr(value: dxr::Value) -> Result<Value, String> {
    Ok(match value {
        dxr::Value::Integer(i) => Value::Int(i),
        dxr::Value::Double(d) => Value::Double(d),
        dxr::Value::Boolean(b) => Value::Bool(b),
        dxr::Value::String(s) => Value::String(s),
        dxr::Value::Array(items) => {
            Value::Array(items.into_iter().map(from_dxr).collect::<Result<_, _>>()?)
        }
        dxr::Value::Nil => Value::Nil,
        dxr::Value::Struct(_) => return Err("unsupported XML-RPC type struct".into()),
        dxr::Value::Base64(_) => return Err("unsupported XML-RPC type base64".into()),
        dxr::Value::DateTime(_) => {
            return Err("unsupported XML-RPC type dateTime.iso8601".into());
        }
        _ => return Err("unsupported XML-RPC type".into()),
    })
}

const XML_DECLARATION: &str = "<?xml version=\"1.0\"?>\n";

/// A short, printable excerpt of a document, for error messages.
pub(crate) fn excerpt(text: &str) -> String {
    let mut short: String = text.chars().take(120).collect();
    if short.len() < text.len() {
        short.push('…');
    }
    short.escape_debug().to_string()
}

/// The XML of a `methodCall`.
pub fn call_to_xml(method: &str, params: &[Value]) -> Result<String, String> {
    let call = dxr::MethodCall {
        name: method.into(),
        params: params.iter().map(to_dxr).collect(),
    };
    let xml = call.to_xml().map_err(|e| e.to_string())?;
    Ok(format!("{XML_DECLARATION}{xml}"))
}

/// The method name and parameters of a `methodCall` document.
pub fn parse_call(xml: &str) -> Result<(String, Vec<Value>), String> {
    let call = dxr::MethodCall::from_xml(xml)
        .map_err(|_| format!("not an XML-RPC methodCall: {}", excerpt(xml)))?;
    let params = call
        .params
        .into_iter()
        .map(from_dxr)
        .collect::<Result<Vec<_>, _>>()?;
    Ok((call.name.into_owned(), params))
}

/// The XML of a `methodResponse`: the value, or the fault.
pub fn response_to_xml(result: &Result<Value, Fault>) -> Result<String, String> {
    let xml = match result {
        Ok(value) => dxr::MethodResponse {
            value: to_dxr(value),
        }
        .to_xml(),
        Err(fault) => dxr::FaultResponse {
            fault: dxr::Fault::new(fault.code, fault.message.clone()),
        }
        .to_xml(),
    }
    .map_err(|e| e.to_string())?;
    Ok(format!("{XML_DECLARATION}{xml}"))
}

/// Reads a `methodResponse` document: `Ok(Ok(value))`, `Ok(Err(fault))`, or an error for
/// anything else.
pub fn parse_response(xml: &str) -> Result<Result<Value, Fault>, String> {
    if let Ok(response) = dxr::MethodResponse::from_xml(xml) {
        return from_dxr(response.value).map(Ok);
    }
    if let Ok(fault) = dxr::FaultResponse::from_xml(xml) {
        return Ok(Err(Fault::new(
            fault.fault.code(),
            fault.fault.string().to_string(),
        )));
    }
    Err(format!("not an XML-RPC methodResponse: {}", excerpt(xml)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What Python's `xmlrpc.client.dumps((1, 2.5, [1.0, 2.0], 'x', True, None),
    /// 'MoveJ', allow_none=True)` writes.
    const PYTHON_CALL: &str = "<?xml version='1.0'?>\n<methodCall>\n<methodName>MoveJ</methodName>\n<params>\n<param>\n<value><int>1</int></value>\n</param>\n<param>\n<value><double>2.5</double></value>\n</param>\n<param>\n<value><array><data>\n<value><double>1.0</double></value>\n<value><double>2.0</double></value>\n</data></array></value>\n</param>\n<param>\n<value><string>x</string></value>\n</param>\n<param>\n<value><boolean>1</boolean></value>\n</param>\n<param>\n<value><nil/></value></param>\n</params>\n</methodCall>\n";

    #[test]
    fn parses_what_python_sends() {
        let (name, params) = parse_call(PYTHON_CALL).unwrap();
        assert_eq!(name, "MoveJ");
        assert_eq!(
            params,
            vec![
                Value::Int(1),
                Value::Double(2.5),
                Value::doubles(&[1.0, 2.0]),
                Value::from("x"),
                Value::Bool(true),
                Value::Nil,
            ]
        );
    }

    #[test]
    fn i4_bare_strings_and_no_params() {
        let xml = "<methodCall><methodName>f</methodName><params><param><value><i4>-7</i4></value></param><param><value>bare text</value></param></params></methodCall>";
        let (_, params) = parse_call(xml).unwrap();
        assert_eq!(params, vec![Value::Int(-7), Value::from("bare text")]);
        let (name, params) =
            parse_call("<methodCall><methodName>GetControllerIP</methodName></methodCall>")
                .unwrap();
        assert_eq!((name.as_str(), params.len()), ("GetControllerIP", 0));
    }

    #[test]
    fn call_round_trip() {
        let params = vec![
            Value::doubles(&[1.5, -2.0, 1e-7]),
            Value::Int(3),
            Value::from("a<b&c"),
            Value::Array(vec![]),
        ];
        let xml = call_to_xml("ServoJ", &params).unwrap();
        assert_eq!(parse_call(&xml).unwrap(), ("ServoJ".to_string(), params));
    }

    #[test]
    fn response_round_trips() {
        let value = Value::Array(vec![Value::Int(0), Value::from("192.168.58.2")]);
        let xml = response_to_xml(&Ok(value.clone())).unwrap();
        assert_eq!(parse_response(&xml).unwrap(), Ok(value));
        let fault = Fault::new(4, "bad <params>");
        let xml = response_to_xml(&Err(fault.clone())).unwrap();
        assert_eq!(parse_response(&xml).unwrap(), Err(fault));
    }

    #[test]
    fn garbage_and_unsupported_types_are_errors() {
        assert!(parse_response("<html>hello</html>").is_err());
        assert!(parse_response("").is_err());
        assert!(parse_call("<methodCall>").is_err());
        let with_struct = "<methodResponse><params><param><value><struct><member><name>a</name><value><int>1</int></value></member></struct></value></param></params></methodResponse>";
        let err = parse_response(with_struct).unwrap_err();
        assert!(err.contains("struct"), "{err}");
    }

    #[test]
    fn helpers() {
        assert_eq!(Value::Int(3).as_f64(), Some(3.0));
        assert_eq!(Value::Double(3.5).as_i64(), None);
        assert_eq!(Value::from("x").as_str(), Some("x"));
        assert_eq!(
            Value::doubles(&[1.0]).as_array().map(<[Value]>::len),
            Some(1)
        );
        assert_eq!(Value::Nil.type_name(), "nil");
        assert_eq!(Value::Bool(true).as_bool(), Some(true));
    }
}
