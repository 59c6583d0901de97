//! The part of GenICam that camera control needs: a camera's XML description read into a node
//! map, and features read and written through it.
//!
//! In: the bytes of the GenICam file from a USB3 Vision camera's manifest, plain or zipped
//! ([`zip`]). Out: a [`NodeMap`] ([`nodes`]: which node kinds are understood and which are
//! refused, by name), read through [`xml`] with the quick-xml crate; formulas of converters and
//! SwissKnives through [`formula`].

pub mod formula;
pub mod nodes;
pub mod xml;
pub mod zip;

pub use nodes::{NodeError, NodeErrorKind, NodeMap, Port};

/// The node map of a GenICam file's bytes (`zipped`: the manifest says it is a ZIP archive).
pub fn load(bytes: &[u8], zipped: bool) -> Result<NodeMap, String> {
    let xml_bytes;
    let bytes = if zipped {
        xml_bytes = zip::xml_from_zip(bytes)?;
        &xml_bytes[..]
    } else {
        bytes
    };
    // Some cameras pad the file with zero bytes up to the register block's size.
    let end = bytes.iter().rposition(|&b| b != 0).map_or(0, |i| i + 1);
    let text = std::str::from_utf8(&bytes[..end]).map_err(|e| format!("the GenICam file is not UTF-8: {e}"))?;
    let root = xml::parse(text).map_err(|e| format!("GenICam file: {e}"))?;
    if root.name != "RegisterDescription" {
        return Err(format!(
            "GenICam file: the root element is <{}>, not <RegisterDescription>",
            root.name
        ));
    }
    Ok(NodeMap::new(&root))
}
