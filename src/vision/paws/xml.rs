//! OpenCV's cascade XML: the format `opencv_traincascade` writes and `CascadeClassifier`
//! reads (`<opencv_storage><cascade type_id="opencv-cascade-classifier">`).
//!
//! We read that format with BOOST stages over HAAR features (upright rectangles; stumps or
//! deeper ordered trees), and the older `opencv-haar-classifier` format for stump cascades;
//! we write the current format. LBP and HOG features, tilted Haar features and categorical
//! trees are refused with an error naming them.
//!
//! Numbers are written with 17 significant digits, so every single-precision value reads
//! back bit for bit, here and in OpenCV.

use super::PawError;
use super::cascade::{BoostStage, Cascade, CascadeParams, Node, WeakTree};
use super::haar::{HaarFeature, HaarRect};
use roxmltree::{Document, Node as XmlNode};
use std::fmt::Write as _;
use std::path::Path;

/// OpenCV's largest shipped cascades are about 2 MB.
const MAX_XML_BYTES: u64 = 64 << 20;

/// Reads a cascade file.
///
/// # Errors
/// When the file cannot be read, is not well-formed XML, is not a cascade, is damaged or
/// uses something we do not support; the error names the file and what is wrong.
pub fn load(path: &Path) -> Result<Cascade, PawError> {
    let bytes = crate::io::read_bounded_bytes(path, MAX_XML_BYTES).map_err(|source| PawError::Io {
        path: path.to_owned(),
        action: "read",
        source,
    })?;
    let text = String::from_utf8(bytes).map_err(|_| PawError::Format {
        path: path.to_owned(),
        reason: "it is not UTF-8 text".to_owned(),
    })?;
    parse(&text, path)
}

/// Whether number text is a finite number's: Rust parses `nan` and `inf`, OpenCV writes
/// neither.
fn finite(t: &str) -> bool {
    !t.trim_start_matches(['+', '-'])
        .starts_with(|c: char| c.is_ascii_alphabetic())
}

/// Deeper than any cascade (OpenCV's nest about six levels): refused before parsing, whose
/// recursion a hostile file could otherwise drive off the stack.
const MAX_NESTING: usize = 64;

/// How deep the elements of `text` nest, counted from its tags alone (comments, processing
/// instructions and declarations skipped; the parser checks the rest).
fn nesting(text: &str) -> usize {
    let (mut depth, mut deepest) = (0usize, 0usize);
    let mut rest = text;
    while let Some(at) = rest.find('<') {
        rest = &rest[at + 1..];
        if let Some(after) = rest.strip_prefix("!--") {
            rest = after.find("-->").map_or("", |end| &after[end + 3..]);
        } else if rest.starts_with('/') {
            depth = depth.saturating_sub(1);
        } else if !rest.starts_with('?') && !rest.starts_with('!') {
            let end = rest.find('>').unwrap_or(rest.len());
            if !rest[..end].ends_with('/') {
                depth += 1;
                deepest = deepest.max(depth);
            }
        }
    }
    deepest
}

/// Parses cascade XML held in memory; `path` only names it in errors.
///
/// # Errors
/// As [`load`].
pub fn parse(text: &str, path: &Path) -> Result<Cascade, PawError> {
    let p = Parser { path };
    let depth = nesting(text);
    if depth > MAX_NESTING {
        return Err(p.bad(format!(
            "its elements nest {depth} deep; a cascade nests fewer than {MAX_NESTING}"
        )));
    }
    let doc = Document::parse(text).map_err(|source| PawError::Xml {
        path: path.to_owned(),
        source,
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "opencv_storage" {
        return Err(p.bad(format!(
            "its root element is <{}>, not <opencv_storage>",
            root.tag_name().name()
        )));
    }
    let top = root
        .children()
        .find(XmlNode::is_element)
        .ok_or_else(|| p.bad("<opencv_storage> is empty".to_owned()))?;
    let cascade = match top.attribute("type_id") {
        Some("opencv-haar-classifier") => p.old_format(top)?,
        Some("opencv-cascade-classifier") | None => p.new_format(top)?,
        Some(other) => return Err(p.bad(format!("its top node has type_id {other:?}"))),
    };
    p.check(&cascade)?;
    let min_neighbors = match child(root, DETECTION_NODE).and_then(|d| child(d, "minNeighbors")) {
        Some(n) => Some(self::text(n).parse::<u32>().map_err(|_| {
            p.bad(format!(
                "<{DETECTION_NODE}><minNeighbors> is {:?}, not a whole number",
                self::text(n)
            ))
        })?),
        None => None,
    };
    Ok(Cascade {
        min_neighbors,
        ..cascade
    })
}

/// The node after the cascade that keeps what mousepose's detector should run it with (the
/// grouping chosen in training); OpenCV reads only the first node and skips it.
const DETECTION_NODE: &str = "mousepose_detection";

struct Parser<'a> {
    path: &'a Path,
}

fn child<'a, 'i>(node: XmlNode<'a, 'i>, name: &str) -> Option<XmlNode<'a, 'i>> {
    node.children().find(|c| c.is_element() && c.tag_name().name() == name)
}

fn items<'a, 'i>(node: XmlNode<'a, 'i>) -> impl Iterator<Item = XmlNode<'a, 'i>> {
    node.children().filter(|c| c.is_element() && c.tag_name().name() == "_")
}

fn text<'a>(node: XmlNode<'a, '_>) -> &'a str {
    node.text().unwrap_or("").trim()
}

impl Parser<'_> {
    fn bad(&self, reason: String) -> PawError {
        PawError::Format {
            path: self.path.to_owned(),
            reason,
        }
    }

    fn unsupported(&self, what: String) -> PawError {
        PawError::Unsupported {
            path: self.path.to_owned(),
            what,
        }
    }

    fn need<'a, 'i>(&self, node: XmlNode<'a, 'i>, name: &str) -> Result<XmlNode<'a, 'i>, PawError> {
        child(node, name).ok_or_else(|| self.bad(format!("<{}> has no <{name}>", node.tag_name().name())))
    }

    fn num<T: std::str::FromStr>(&self, node: XmlNode<'_, '_>, what: &str) -> Result<T, PawError> {
        let t = text(node);
        finite(t)
            .then(|| t.parse().ok())
            .flatten()
            .ok_or_else(|| self.bad(format!("<{what}> holds {t:?}, not a number")))
    }

    fn field<T: std::str::FromStr>(&self, node: XmlNode<'_, '_>, name: &str) -> Result<T, PawError> {
        self.num(self.need(node, name)?, name)
    }

    /// Whitespace-separated numbers, read as OpenCV reads them: doubles, then narrowed.
    fn numbers(&self, node: XmlNode<'_, '_>, what: &str) -> Result<Vec<f64>, PawError> {
        text(node)
            .split_whitespace()
            .map(|t| {
                finite(t)
                    .then(|| t.parse::<f64>().ok())
                    .flatten()
                    .ok_or_else(|| self.bad(format!("<{what}> holds {t:?}, not a number")))
            })
            .collect()
    }

    fn int(&self, v: f64, what: &str) -> Result<i32, PawError> {
        if v.fract() != 0.0 || v.abs() > 1e9 {
            return Err(self.bad(format!("<{what}> holds {v}, not a whole number")));
        }
        Ok(v as i32)
    }

    fn rects(&self, feature: XmlNode<'_, '_>) -> Result<HaarFeature, PawError> {
        if let Some(t) = child(feature, "tilted") {
            if text(t) != "0" {
                return Err(self.unsupported("tilted Haar features".to_owned()));
            }
        }
        let rects = self.need(feature, "rects")?;
        let mut out = Vec::new();
        for r in items(rects) {
            let v = self.numbers(r, "rects")?;
            if v.len() != 5 {
                return Err(self.bad(format!("a feature rectangle has {} numbers instead of 5", v.len())));
            }
            let dims: Vec<i32> = v[..4].iter().map(|&x| self.int(x, "rects")).collect::<Result<_, _>>()?;
            if dims.iter().any(|&d| d < 0) {
                return Err(self.bad(format!("a feature rectangle has a negative side or corner: {dims:?}")));
            }
            out.push(HaarRect {
                x: dims[0] as u32,
                y: dims[1] as u32,
                width: dims[2] as u32,
                height: dims[3] as u32,
                weight: v[4] as f32,
            });
        }
        if !(2..=3).contains(&out.len()) {
            return Err(self.bad(format!("a feature has {} rectangles (2 or 3 expected)", out.len())));
        }
        Ok(HaarFeature { rects: out })
    }

    fn new_format(&self, top: XmlNode<'_, '_>) -> Result<Cascade, PawError> {
        let stage_type = text(self.need(top, "stageType")?);
        if stage_type != "BOOST" {
            return Err(self.unsupported(format!("stage type {stage_type:?}")));
        }
        let feature_type = text(self.need(top, "featureType")?);
        if feature_type != "HAAR" {
            return Err(self.unsupported(format!("{feature_type} features")));
        }
        let height: u32 = self.field(top, "height")?;
        let width: u32 = self.field(top, "width")?;
        let params = self.new_params(top)?;
        let stage_num: usize = self.field(top, "stageNum")?;
        let mut stages = Vec::new();
        for (k, s) in items(self.need(top, "stages")?).enumerate() {
            stages.push(self.new_stage(k, s)?);
        }
        if stages.len() != stage_num {
            return Err(self.bad(format!(
                "<stageNum> is {stage_num} but {} stages are present",
                stages.len()
            )));
        }
        let features = items(self.need(top, "features")?)
            .map(|f| self.rects(f))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Cascade {
            width,
            height,
            params,
            stages,
            features,
            min_neighbors: None,
        })
    }

    /// The new format's training parameters (`stageParams`, `featureParams`), as far as they
    /// are given; categorical features are refused.
    fn new_params(&self, top: XmlNode<'_, '_>) -> Result<CascadeParams, PawError> {
        let mut params = CascadeParams::default();
        if let Some(sp) = child(top, "stageParams") {
            if let Some(n) = child(sp, "boostType") {
                text(n).clone_into(&mut params.boost_type);
            }
            if let Some(n) = child(sp, "minHitRate") {
                params.min_hit_rate = self.num::<f64>(n, "minHitRate")? as f32;
            }
            if let Some(n) = child(sp, "maxFalseAlarm") {
                params.max_false_alarm = self.num::<f64>(n, "maxFalseAlarm")? as f32;
            }
            if let Some(n) = child(sp, "weightTrimRate") {
                params.weight_trim_rate = self.num::<f64>(n, "weightTrimRate")? as f32;
            }
            if let Some(n) = child(sp, "maxDepth") {
                params.max_depth = self.num(n, "maxDepth")?;
            }
            if let Some(n) = child(sp, "maxWeakCount") {
                params.max_weak_count = self.num(n, "maxWeakCount")?;
            }
        }
        if let Some(fp) = child(top, "featureParams") {
            if let Some(n) = child(fp, "maxCatCount") {
                let cats: u32 = self.num(n, "maxCatCount")?;
                if cats != 0 {
                    return Err(self.unsupported("categorical features (maxCatCount > 0)".to_owned()));
                }
            }
            if let Some(n) = child(fp, "mode") {
                text(n).clone_into(&mut params.mode);
            }
        }
        Ok(params)
    }

    /// Stage `k` of the new format: its threshold and weak classifiers, each checked.
    fn new_stage(&self, k: usize, s: XmlNode<'_, '_>) -> Result<BoostStage, PawError> {
        let threshold = self.field::<f64>(s, "stageThreshold")? as f32;
        let mut weak = Vec::new();
        for w in items(self.need(s, "weakClassifiers")?) {
            let nodes = self.numbers(self.need(w, "internalNodes")?, "internalNodes")?;
            let leaves = self.numbers(self.need(w, "leafValues")?, "leafValues")?;
            if nodes.is_empty() || nodes.len() % 4 != 0 {
                return Err(self.bad(format!(
                    "a weak classifier of stage {k} has {} internal-node numbers (4 per node expected)",
                    nodes.len()
                )));
            }
            let nodes = nodes
                .chunks(4)
                .map(|c| {
                    let feature = self.int(c[2], "internalNodes")?;
                    Ok(Node {
                        left: self.int(c[0], "internalNodes")?,
                        right: self.int(c[1], "internalNodes")?,
                        feature: usize::try_from(feature)
                            .map_err(|_| self.bad(format!("a node names feature {feature}")))?,
                        threshold: c[3] as f32,
                    })
                })
                .collect::<Result<Vec<_>, PawError>>()?;
            weak.push(WeakTree {
                nodes,
                leaves: leaves.iter().map(|&v| v as f32).collect(),
            });
        }
        if let Some(n) = child(s, "maxWeakCount") {
            let declared: usize = self.num(n, "maxWeakCount")?;
            if declared != weak.len() {
                return Err(self.bad(format!(
                    "stage {k} declares {declared} weak classifiers but holds {}",
                    weak.len()
                )));
            }
        }
        Ok(BoostStage { threshold, weak })
    }

    /// The older format: each tree node carries its own feature, stumps only.
    fn old_format(&self, top: XmlNode<'_, '_>) -> Result<Cascade, PawError> {
        let size = self.numbers(self.need(top, "size")?, "size")?;
        if size.len() != 2 {
            return Err(self.bad("<size> does not hold a width and a height".to_owned()));
        }
        let (width, height) = (self.int(size[0], "size")?, self.int(size[1], "size")?);
        let mut features = Vec::new();
        let mut stages = Vec::new();
        for s in items(self.need(top, "stages")?) {
            let threshold = self.field::<f64>(s, "stage_threshold")? as f32;
            let mut weak = Vec::new();
            for tree in items(self.need(s, "trees")?) {
                let nodes: Vec<_> = items(tree).collect();
                if nodes.len() != 1 {
                    return Err(self.unsupported("old-format trees deeper than one node".to_owned()));
                }
                let node = nodes[0];
                let feature = self.rects(self.need(node, "feature")?)?;
                let t = self.field::<f64>(node, "threshold")? as f32;
                let left = self.field::<f64>(node, "left_val")? as f32;
                let right = self.field::<f64>(node, "right_val")? as f32;
                weak.push(WeakTree::stump(features.len(), t, left, right));
                features.push(feature);
            }
            stages.push(BoostStage { threshold, weak });
        }
        Ok(Cascade {
            width: u32::try_from(width).map_err(|_| self.bad(format!("window width {width}")))?,
            height: u32::try_from(height).map_err(|_| self.bad(format!("window height {height}")))?,
            params: CascadeParams::default(),
            stages,
            features,
            min_neighbors: None,
        })
    }

    /// Everything the evaluator relies on: sizes, indices in range, trees that end.
    fn check(&self, c: &Cascade) -> Result<(), PawError> {
        if c.width < 3 || c.height < 3 || c.width > 1024 || c.height > 1024 {
            return Err(self.bad(format!("its window is {}x{} pixels", c.width, c.height)));
        }
        if c.stages.is_empty() {
            return Err(self.bad("it has no stages".to_owned()));
        }
        for (k, f) in c.features.iter().enumerate() {
            if !f.fits(c.width, c.height) {
                return Err(self.bad(format!("feature {k} does not fit the {}x{} window", c.width, c.height)));
            }
        }
        for (k, stage) in c.stages.iter().enumerate() {
            if stage.weak.is_empty() {
                return Err(self.bad(format!("stage {k} has no weak classifiers")));
            }
            for tree in &stage.weak {
                let n = tree.nodes.len() as i32;
                for (i, node) in tree.nodes.iter().enumerate() {
                    if node.feature >= c.features.len() {
                        return Err(self.bad(format!(
                            "stage {k} uses feature {} of {}",
                            node.feature,
                            c.features.len()
                        )));
                    }
                    for child in [node.left, node.right] {
                        let leaf_ok = child <= 0 && ((-child) as usize) < tree.leaves.len();
                        let node_ok = child > i as i32 && child < n;
                        if !leaf_ok && !node_ok {
                            return Err(self.bad(format!(
                                "a tree of stage {k} points to a missing node or leaf ({child})"
                            )));
                        }
                    }
                    if !node.threshold.is_finite() {
                        return Err(self.bad(format!("a threshold of stage {k} is not finite")));
                    }
                }
                if tree.leaves.iter().any(|v| !v.is_finite()) {
                    return Err(self.bad(format!("a leaf value of stage {k} is not finite")));
                }
            }
        }
        Ok(())
    }
}

fn real(v: f32) -> String {
    format!("{:.16e}", f64::from(v))
}

fn weight(v: f32) -> String {
    if v.fract() == 0.0 && v.abs() < 1e6 {
        format!("{}.", v as i64)
    } else {
        real(v)
    }
}

/// The cascade as OpenCV cascade XML.
pub fn to_xml(c: &Cascade) -> String {
    let p = &c.params;
    let mut s = String::with_capacity(64 * 1024);
    s.push_str("<?xml version=\"1.0\"?>\n<opencv_storage>\n<cascade type_id=\"opencv-cascade-classifier\">\n");
    let _ = writeln!(s, "  <stageType>BOOST</stageType>");
    let _ = writeln!(s, "  <featureType>HAAR</featureType>");
    let _ = writeln!(s, "  <height>{}</height>\n  <width>{}</width>", c.height, c.width);
    let _ = writeln!(
        s,
        "  <stageParams>\n    <boostType>{}</boostType>\n    <minHitRate>{}</minHitRate>\n    \
         <maxFalseAlarm>{}</maxFalseAlarm>\n    <weightTrimRate>{}</weightTrimRate>\n    \
         <maxDepth>{}</maxDepth>\n    <maxWeakCount>{}</maxWeakCount></stageParams>",
        p.boost_type,
        real(p.min_hit_rate),
        real(p.max_false_alarm),
        real(p.weight_trim_rate),
        p.max_depth,
        p.max_weak_count
    );
    let _ = writeln!(
        s,
        "  <featureParams>\n    <maxCatCount>0</maxCatCount>\n    <featureSize>1</featureSize>\n    \
         <mode>{}</mode></featureParams>",
        p.mode
    );
    let _ = writeln!(s, "  <stageNum>{}</stageNum>\n  <stages>", c.stages.len());
    for (k, stage) in c.stages.iter().enumerate() {
        let _ = writeln!(s, "    <!-- stage {k} -->\n    <_>");
        let _ = writeln!(s, "      <maxWeakCount>{}</maxWeakCount>", stage.weak.len());
        let _ = writeln!(s, "      <stageThreshold>{}</stageThreshold>", real(stage.threshold));
        s.push_str("      <weakClassifiers>\n");
        for tree in &stage.weak {
            s.push_str("        <_>\n          <internalNodes>\n           ");
            for n in &tree.nodes {
                let _ = write!(s, " {} {} {} {}", n.left, n.right, n.feature, real(n.threshold));
            }
            s.push_str("</internalNodes>\n          <leafValues>\n           ");
            for v in &tree.leaves {
                let _ = write!(s, " {}", real(*v));
            }
            s.push_str("</leafValues></_>\n");
        }
        s.push_str("      </weakClassifiers></_>\n");
    }
    s.push_str("  </stages>\n  <features>\n");
    for f in &c.features {
        s.push_str("    <_>\n      <rects>\n");
        for r in &f.rects {
            let _ = writeln!(
                s,
                "        <_>\n          {} {} {} {} {}</_>",
                r.x,
                r.y,
                r.width,
                r.height,
                weight(r.weight)
            );
        }
        s.push_str("      </rects>\n      <tilted>0</tilted></_>\n");
    }
    s.push_str("  </features>\n</cascade>\n");
    if let Some(n) = c.min_neighbors {
        let _ = writeln!(
            s,
            "<{DETECTION_NODE}>\n  <minNeighbors>{n}</minNeighbors>\n</{DETECTION_NODE}>"
        );
    }
    s.push_str("</opencv_storage>\n");
    s
}

/// Writes the cascade to `path` atomically: a temporary file beside it, then a rename, so a
/// reader never sees half a cascade.
///
/// # Errors
/// When the file cannot be written or renamed into place.
pub fn save(c: &Cascade, path: &Path) -> Result<(), PawError> {
    let io = |action, source| PawError::Io {
        path: path.to_owned(),
        action,
        source,
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "cascade.xml".to_owned());
    let tmp = path.with_file_name(format!(".{name}.tmp{}", std::process::id()));
    std::fs::write(&tmp, to_xml(c)).map_err(|e| io("write", e))?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io("rename into place", e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> Cascade {
        Cascade {
            width: 6,
            height: 5,
            min_neighbors: None,
            params: CascadeParams::default(),
            stages: vec![
                BoostStage {
                    threshold: -0.123_456_79,
                    weak: vec![
                        WeakTree::stump(0, 0.015, -1.0, 0.75),
                        WeakTree::stump(1, -0.3, 0.5, -0.25),
                    ],
                },
                BoostStage {
                    threshold: 0.1,
                    weak: vec![WeakTree::stump(1, 1e-7, 0.1, -0.1)],
                },
            ],
            features: vec![
                HaarFeature {
                    rects: vec![
                        HaarRect {
                            x: 0,
                            y: 0,
                            width: 6,
                            height: 2,
                            weight: -1.0,
                        },
                        HaarRect {
                            x: 0,
                            y: 1,
                            width: 6,
                            height: 1,
                            weight: 2.0,
                        },
                    ],
                },
                HaarFeature {
                    rects: vec![
                        HaarRect {
                            x: 1,
                            y: 1,
                            width: 4,
                            height: 4,
                            weight: -1.0,
                        },
                        HaarRect {
                            x: 1,
                            y: 1,
                            width: 2,
                            height: 2,
                            weight: 2.0,
                        },
                        HaarRect {
                            x: 3,
                            y: 3,
                            width: 2,
                            height: 2,
                            weight: 2.0,
                        },
                    ],
                },
            ],
        }
    }

    #[test]
    fn round_trip_is_identical() {
        let c = tiny();
        let back = parse(&to_xml(&c), Path::new("tiny.xml")).unwrap();
        assert_eq!(back, c);
        // The grouping chosen in training rides after the cascade.
        let grouped = Cascade {
            min_neighbors: Some(4),
            ..tiny()
        };
        let xml = to_xml(&grouped);
        assert!(xml.find("</cascade>") < xml.find("<mousepose_detection>"));
        assert_eq!(parse(&xml, Path::new("g.xml")).unwrap(), grouped);
        let bad = xml.replace("<minNeighbors>4", "<minNeighbors>four");
        let e = parse(&bad, Path::new("g.xml")).unwrap_err().to_string();
        assert!(e.contains("minNeighbors") && e.contains("g.xml"), "{e}");
    }

    #[test]
    fn damage_is_named() {
        let xml = to_xml(&tiny());
        let cut = &xml[..xml.len() / 2];
        let e = parse(cut, Path::new("cut.xml")).unwrap_err();
        assert!(matches!(e, PawError::Xml { .. }), "{e}");
        assert!(e.to_string().contains("cut.xml"));
        let lbp = xml.replace("<featureType>HAAR", "<featureType>LBP");
        let e = parse(&lbp, Path::new("lbp.xml")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "cascade \"lbp.xml\" uses LBP features, which mousepose does not support"
        );
        let tilted = xml.replacen("<tilted>0", "<tilted>1", 1);
        assert!(matches!(
            parse(&tilted, Path::new("t.xml")),
            Err(PawError::Unsupported { .. })
        ));
        let wrong = xml.replace("0 -1 1 ", "0 -1 7 ");
        let e = parse(&wrong, Path::new("w.xml")).unwrap_err();
        assert!(e.to_string().contains("uses feature 7 of 2"), "{e}");
        let nan = xml.replacen("<stageThreshold>", "<stageThreshold>x", 1);
        assert!(matches!(parse(&nan, Path::new("n.xml")), Err(PawError::Format { .. })));
        for bad in ["nan", "-inf", "Infinity"] {
            let at = xml.find("<stageThreshold>").unwrap() + "<stageThreshold>".len();
            let end = at + xml[at..].find('<').unwrap();
            let text = format!("{}{bad}{}", &xml[..at], &xml[end..]);
            let e = parse(&text, Path::new("n.xml")).unwrap_err().to_string();
            assert!(e.contains("not a number"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_cascade_nested_thousands_deep_is_refused_not_a_stack_overflow() {
        let d = 30_000;
        let text = format!(
            "<opencv_storage>{}{}</opencv_storage>",
            "<a>".repeat(d),
            "</a>".repeat(d)
        );
        let e = parse(&text, Path::new("deep.xml")).unwrap_err().to_string();
        assert!(e.contains("nest 30001 deep"), "{e}");
        assert_eq!(nesting("<?xml version=\"1.0\"?><!-- <x> --><a><b/><c>1</c></a>"), 2);
    }
}
