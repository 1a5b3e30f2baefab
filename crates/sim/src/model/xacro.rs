//! Telling real xacro apart from plain URDF that xacro generated.
//!
//! ROS packages ship URDFs expanded by xacro that still declare `xmlns:xacro` on `<robot>`; they
//! are plain URDF and load. A description is xacro only if it uses the language: an element in the
//! xacro namespace (`<xacro:macro>`, `<xacro:include>`, `<xacro:property>`, …, whatever prefix is
//! bound to it) or a `${…}` / `$(…)` substitution in an attribute value. The file name does not
//! matter.

/// The namespace URIs xacro files bind their prefix to (the second is the older spelling).
const XACRO_NAMESPACES: [&str; 2] = ["http://www.ros.org/wiki/xacro", "http://ros.org/wiki/xacro"];

/// The longest attribute value quoted in a message.
const MAX_QUOTED: usize = 60;

/// The first xacro construct in document order: its line and a description of it.
pub(super) fn first_xacro_construct(doc: &roxmltree::Document) -> Option<(u32, String)> {
    doc.descendants()
        .filter(|n| n.is_element())
        .find_map(|node| {
            let tag = qualified_name(node);
            if node
                .tag_name()
                .namespace()
                .is_some_and(|ns| XACRO_NAMESPACES.contains(&ns))
            {
                let line = doc.text_pos_at(node.range().start).row;
                return Some((line, format!("xacro element <{tag}>")));
            }
            node.attributes().find_map(|attribute| {
                let value = attribute.value();
                if !(value.contains("${") || value.contains("$(")) {
                    return None;
                }
                let line = doc.text_pos_at(attribute.range().start).row;
                Some((
                    line,
                    format!(
                        "xacro substitution \"{}\" in <{tag} {}>",
                        quoted(value),
                        attribute.name()
                    ),
                ))
            })
        })
}

/// The element's name with the prefix the file uses for its namespace, e.g. `xacro:macro`.
fn qualified_name(node: roxmltree::Node) -> String {
    let name = node.tag_name().name();
    match node
        .tag_name()
        .namespace()
        .and_then(|ns| node.lookup_prefix(ns))
    {
        Some(prefix) if !prefix.is_empty() => format!("{prefix}:{name}"),
        _ => name.to_string(),
    }
}

fn quoted(value: &str) -> String {
    match value.char_indices().nth(MAX_QUOTED) {
        Some((cut, _)) => format!("{}…", &value[..cut]),
        None => value.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn find(text: &str) -> Option<(u32, String)> {
        first_xacro_construct(&roxmltree::Document::parse(text).unwrap())
    }

    #[test]
    fn a_namespace_declaration_alone_is_not_xacro() {
        let text = r#"<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <link name="base"><visual><geometry><mesh filename="package://p/m.stl"/></geometry></visual></link>
</robot>"#;
        assert_eq!(find(text), None);
    }

    #[test]
    fn elements_are_found_by_namespace_whatever_their_prefix() {
        let text = r#"<robot name="r" xmlns:x="http://ros.org/wiki/xacro">
  <link name="base"/>
  <x:macro name="m" params="p"/>
</robot>"#;
        assert_eq!(find(text), Some((3, "xacro element <x:macro>".to_string())));
        // The prefix `xacro` bound to another namespace is not xacro.
        let other = r#"<robot name="r" xmlns:xacro="urn:something-else"><xacro:macro/></robot>"#;
        assert_eq!(find(other), None);
    }

    #[test]
    fn substitutions_are_found_in_attribute_values_and_long_values_are_cut() {
        let text = "<robot name=\"r\">\n<link name=\"a\"/>\n<joint name=\"${prefix}j\"/>\n</robot>";
        assert_eq!(
            find(text),
            Some((
                3,
                "xacro substitution \"${prefix}j\" in <joint name>".to_string()
            ))
        );
        let long = format!("$(find pkg)/{}", "a".repeat(100));
        let text = format!("<robot name=\"r\"><mesh filename=\"{long}\"/></robot>");
        let (_, found) = find(&text).unwrap();
        assert!(
            found.contains(&format!("\"{}…\"", &long[..MAX_QUOTED])),
            "{found}"
        );
    }
}
