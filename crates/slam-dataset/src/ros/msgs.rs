//! The few ROS 2 message types the system reads from a bag (`sensor_msgs/msg/Image`,
//! `CompressedImage`, `CameraInfo`: their headers and what a stereo run needs) and the ones a run's
//! results are written as (`tf2_msgs/msg/TFMessage`, `nav_msgs/msg/Path`,
//! `visualization_msgs/msg/MarkerArray`, `sensor_msgs/msg/PointCloud2`), with the `ros2msg` schema
//! text of each written type (the main definition, then every type it uses under a `MSG:` line, as a
//! ROS 2 bag stores it), so that a viewer decodes the file without a ROS installation.

use nalgebra::{Isometry3, Point3, Vector3};

use super::cdr::{CdrError, CdrReader, CdrWriter};

/// Schema name of a raw image.
pub const IMAGE: &str = "sensor_msgs/msg/Image";
/// Schema name of a compressed image.
pub const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
/// Schema name of a camera's calibration.
pub const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";

/// A message header: its time stamp and the sensor's frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    /// `stamp` as nanoseconds since the epoch (seconds · 10⁹ + nanoseconds).
    pub stamp_ns: i64,
    /// The coordinate frame the data is in.
    pub frame_id: String,
}

fn header(r: &mut CdrReader<'_>) -> Result<Header, CdrError> {
    let sec = r.i32("header.stamp.sec")?;
    let at = r.position();
    let nanosec = r.u32("header.stamp.nanosec")?;
    if nanosec >= 1_000_000_000 {
        return Err(CdrError { offset: at, message: format!("header.stamp.nanosec {nanosec} is a second or more") });
    }
    let frame_id = r.string("header.frame_id")?;
    Ok(Header { stamp_ns: i64::from(sec) * 1_000_000_000 + i64::from(nanosec), frame_id })
}

/// The header alone of any message that starts with one (every type read here).
pub fn read_header(data: &[u8]) -> Result<Header, CdrError> {
    header(&mut CdrReader::new(data)?)
}

/// The pixels of one image message, owned, as read from a bag: what the front end decodes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ImagePayload {
    /// `sensor_msgs/msg/Image`: raw pixels.
    Raw {
        /// Width, pixels.
        width: u32,
        /// Height, pixels.
        height: u32,
        /// Pixel layout as ROS names it (`mono8`, `rgb8`, `bgr8`, `mono16`, …).
        encoding: String,
        /// 16-bit pixels stored most significant byte first.
        big_endian: bool,
        /// Bytes per row (at least the width times the pixel size; rows may be padded).
        step: u32,
        /// The rows.
        data: Vec<u8>,
    },
    /// `sensor_msgs/msg/CompressedImage`: an encoded image.
    Compressed {
        /// The format as the message says it (`png`, `jpeg`, `mono8; png compressed`, …).
        format: String,
        /// The encoded file.
        data: Vec<u8>,
    },
}

impl ImagePayload {
    /// Read an image message of schema `schema` ([`IMAGE`] or [`COMPRESSED_IMAGE`]).
    pub fn read(schema: &str, data: &[u8]) -> Result<(Header, ImagePayload), CdrError> {
        let mut r = CdrReader::new(data)?;
        let h = header(&mut r)?;
        let payload = if schema == COMPRESSED_IMAGE {
            let format = r.string("format")?;
            ImagePayload::Compressed { format, data: r.bytes("data")?.to_vec() }
        } else {
            let height = r.u32("height")?;
            let width = r.u32("width")?;
            let encoding = r.string("encoding")?;
            let big_endian = r.u8("is_bigendian")? != 0;
            let step = r.u32("step")?;
            ImagePayload::Raw { width, height, encoding, big_endian, step, data: r.bytes("data")?.to_vec() }
        };
        Ok((h, payload))
    }

    /// What it holds, for messages: `1242×375 mono8` or `png, 301 kB`.
    pub fn describe(&self) -> String {
        match self {
            ImagePayload::Raw { width, height, encoding, .. } => format!("{width}×{height} {encoding}"),
            ImagePayload::Compressed { format, data } => format!("{format}, {} bytes", data.len()),
        }
    }
}

/// The size and pixel layout of an image message, read without copying its pixels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageInfo {
    /// The header.
    pub header: Header,
    /// `(width, height, encoding)` of a raw image; `None` for a compressed one (its size is in its file).
    pub raw: Option<(u32, u32, String)>,
    /// The compressed image's format (empty for a raw one).
    pub format: String,
}

impl ImageInfo {
    /// Read the header and layout of an image message of schema `schema`.
    pub fn read(schema: &str, data: &[u8]) -> Result<ImageInfo, CdrError> {
        let mut r = CdrReader::new(data)?;
        let header = header(&mut r)?;
        if schema == COMPRESSED_IMAGE {
            let format = r.string("format")?;
            // the data must be there in full: a message cut inside it is an error now, not at decoding
            r.bytes("data")?;
            return Ok(ImageInfo { header, raw: None, format });
        }
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        let encoding = r.string("encoding")?;
        r.u8("is_bigendian")?;
        let at = r.position();
        let step = r.u32("step")?;
        let data = r.bytes("data")?;
        let rows = u64::from(step) * u64::from(height);
        if (data.len() as u64) < rows {
            return Err(CdrError {
                offset: at,
                message: format!("data holds {} bytes, {height} rows of step {step} need {rows}", data.len()),
            });
        }
        Ok(ImageInfo { header, raw: Some((width, height, encoding)), format: String::new() })
    }
}

/// A camera's calibration as `sensor_msgs/msg/CameraInfo` carries it (row-major matrices).
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// The header.
    pub header: Header,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`, or empty.
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// The raw camera's intrinsic matrix.
    pub k: [f64; 9],
    /// The rectifying rotation.
    pub r: [f64; 9],
    /// The projection of the rectified camera: `[fx' 0 cx' Tx; 0 fy' cy' Ty; 0 0 1 0]`, with
    /// `Tx = −fx' · B` for the right camera of a pair whose cameras are `B` apart.
    pub p: [f64; 12],
}

impl CameraInfo {
    /// Read a `CameraInfo` message.
    pub fn read(data: &[u8]) -> Result<CameraInfo, CdrError> {
        let mut r = CdrReader::new(data)?;
        let header = header(&mut r)?;
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        let distortion_model = r.string("distortion_model")?;
        let d = r.f64_sequence("d")?;
        let k = r.f64_array::<9>("k")?;
        let rot = r.f64_array::<9>("r")?;
        let p = r.f64_array::<12>("p")?;
        Ok(CameraInfo { header, width, height, distortion_model, d, k, r: rot, p })
    }

    /// Encode (for tests and tools that make bags).
    pub fn write(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        write_header(&mut w, &self.header);
        w.u32(self.height).u32(self.width).string(&self.distortion_model).count(self.d.len()).f64s(&self.d);
        w.f64s(&self.k).f64s(&self.r).f64s(&self.p);
        // binning_x, binning_y, then the region of interest (x, y, height, width, do_rectify)
        w.u32(0).u32(0).u32(0).u32(0).u32(0).u32(0).bool(false);
        w.finish()
    }
}

fn write_header(w: &mut CdrWriter, h: &Header) {
    let (sec, nsec) = (h.stamp_ns.div_euclid(1_000_000_000), h.stamp_ns.rem_euclid(1_000_000_000));
    w.i32(sec as i32).u32(nsec as u32).string(&h.frame_id);
}

/// Encode a raw image message (for tests and tools that make bags).
pub fn write_image(h: &Header, width: u32, height: u32, encoding: &str, step: u32, data: &[u8]) -> Vec<u8> {
    let mut w = CdrWriter::new();
    write_header(&mut w, h);
    w.u32(height).u32(width).string(encoding).u8(0).u32(step).bytes(data);
    w.finish()
}

/// Encode a compressed image message (for tests and tools that make bags).
pub fn write_compressed_image(h: &Header, format: &str, data: &[u8]) -> Vec<u8> {
    let mut w = CdrWriter::new();
    write_header(&mut w, h);
    w.string(format).bytes(data);
    w.finish()
}

// The definitions below are the ROS 2 interfaces' field lists, as a bag's `ros2msg` schema holds them.
const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER_MSG: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const VECTOR3: &str = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
const POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION: &str = "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";
const POSE: &str = "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n";
const SEPARATOR: &str = "================================================================================\n";

fn schema(main: &str, uses: &[&str]) -> String {
    let mut text = main.to_string();
    for u in uses {
        text.push_str(SEPARATOR);
        text.push_str(u);
    }
    text
}

/// The written message types: `(name, ros2msg schema text)`.
pub fn output_schemas() -> [(&'static str, String); 4] {
    let transform =
        "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n";
    let stamped = "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n";
    let pose_stamped = "MSG: geometry_msgs/PoseStamped\nstd_msgs/Header header\ngeometry_msgs/Pose pose\n";
    let color = "MSG: std_msgs/ColorRGBA\nfloat32 r\nfloat32 g\nfloat32 b\nfloat32 a\n";
    let duration = "MSG: builtin_interfaces/Duration\nint32 sec\nuint32 nanosec\n";
    let marker =
        "MSG: visualization_msgs/Marker\nint32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 TEXT_VIEW_FACING=9\n\
                  int32 ADD=0\nint32 DELETE=2\nint32 DELETEALL=3\nstd_msgs/Header header\nstring ns\nint32 id\n\
                  int32 type\nint32 action\ngeometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\n\
                  std_msgs/ColorRGBA color\nbuiltin_interfaces/Duration lifetime\nbool frame_locked\n\
                  geometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\nstring text\nstring mesh_resource\n\
                  bool mesh_use_embedded_materials\n";
    let field = "MSG: sensor_msgs/PointField\nuint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\n\
                 uint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\nstring name\nuint32 offset\n\
                 uint8 datatype\nuint32 count\n";
    [
        (TF, schema("geometry_msgs/TransformStamped[] transforms\n", &[stamped, HEADER_MSG, TIME, transform, VECTOR3, QUATERNION])),
        (PATH, schema("std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n", &[HEADER_MSG, TIME, pose_stamped, POSE, POINT, QUATERNION])),
        (MARKERS, schema("visualization_msgs/Marker[] markers\n", &[marker, HEADER_MSG, TIME, POSE, POINT, QUATERNION, VECTOR3, color, duration])),
        (POINT_CLOUD, schema(
            "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\n\
             uint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
            &[HEADER_MSG, TIME, field],
        )),
    ]
}

/// Schema name of a transform message.
pub const TF: &str = "tf2_msgs/msg/TFMessage";
/// Schema name of a path.
pub const PATH: &str = "nav_msgs/msg/Path";
/// Schema name of a marker array.
pub const MARKERS: &str = "visualization_msgs/msg/MarkerArray";
/// Schema name of a point cloud.
pub const POINT_CLOUD: &str = "sensor_msgs/msg/PointCloud2";

fn write_pose(w: &mut CdrWriter, pose: &Isometry3<f64>) {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    w.f64(t.x).f64(t.y).f64(t.z).f64(q.i).f64(q.j).f64(q.k).f64(q.w);
}

/// A `TFMessage` with one transform: `child` in `parent` (`x_parent = pose · x_child`) at `stamp_ns`.
pub fn tf_message(stamp_ns: i64, parent: &str, child: &str, pose: &Isometry3<f64>) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.count(1);
    write_header(&mut w, &Header { stamp_ns, frame_id: parent.into() });
    w.string(child);
    // a Transform is translation then rotation, as a Pose is position then orientation
    write_pose(&mut w, pose);
    w.finish()
}

/// A `Path` in `frame`: one pose per entry with its own stamp.
pub fn path_message(stamp_ns: i64, frame: &str, poses: &[(i64, Isometry3<f64>)]) -> Vec<u8> {
    let mut w = CdrWriter::new();
    write_header(&mut w, &Header { stamp_ns, frame_id: frame.into() });
    w.count(poses.len());
    for (t, p) in poses {
        write_header(&mut w, &Header { stamp_ns: *t, frame_id: frame.into() });
        write_pose(&mut w, p);
    }
    w.finish()
}

/// One marker of a [`markers_message`]: a scaled sphere (an ellipsoid) or a text facing the viewer.
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Namespace (markers are identified by namespace and id).
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// Pose in the message's frame (a sphere's axes are its pose's axes).
    pub pose: Isometry3<f64>,
    /// A sphere's full extent along its axes (twice the semi-axes), or a text's height in `z`.
    pub scale: Vector3<f64>,
    /// Colour, red, green, blue, opacity in 0-1.
    pub color: [f32; 4],
    /// `Some(text)`: a text marker; `None`: a sphere.
    pub text: Option<String>,
}

/// A `MarkerArray` in `frame`: a delete-all first (a viewer replaces what an earlier array showed), then
/// each marker added.
pub fn markers_message(stamp_ns: i64, frame: &str, markers: &[Marker]) -> Vec<u8> {
    const SPHERE: i32 = 2;
    const TEXT: i32 = 9;
    const DELETE_ALL: i32 = 3;
    let mut w = CdrWriter::new();
    w.count(markers.len() + 1);
    let clear = Marker {
        ns: String::new(),
        id: 0,
        pose: Isometry3::identity(),
        scale: Vector3::zeros(),
        color: [0.0; 4],
        text: None,
    };
    for (k, m) in std::iter::once(&clear).chain(markers).enumerate() {
        write_header(&mut w, &Header { stamp_ns, frame_id: frame.into() });
        w.string(&m.ns).i32(m.id);
        let kind = if m.text.is_some() { TEXT } else { SPHERE };
        w.i32(kind).i32(if k == 0 { DELETE_ALL } else { 0 });
        write_pose(&mut w, &m.pose);
        w.f64(m.scale.x).f64(m.scale.y).f64(m.scale.z);
        w.f32(m.color[0]).f32(m.color[1]).f32(m.color[2]).f32(m.color[3]);
        // lifetime 0: for ever; not locked to its frame; no points, no per-point colours
        w.i32(0).u32(0).bool(false).count(0).count(0);
        w.string(m.text.as_deref().unwrap_or("")).string("").bool(false);
    }
    w.finish()
}

/// A `PointCloud2` of points `x, y, z` (32-bit floats) in `frame`, one row.
pub fn point_cloud_message(stamp_ns: i64, frame: &str, points: &[Point3<f64>]) -> Vec<u8> {
    const FLOAT32: u8 = 7;
    let mut w = CdrWriter::new();
    write_header(&mut w, &Header { stamp_ns, frame_id: frame.into() });
    w.u32(1).u32(points.len() as u32).count(3);
    for (name, offset) in [("x", 0), ("y", 4), ("z", 8)] {
        w.string(name).u32(offset).u8(FLOAT32).u32(1);
    }
    w.bool(false).u32(12).u32(12 * points.len() as u32);
    let mut data = Vec::with_capacity(12 * points.len());
    for p in points {
        for v in [p.x, p.y, p.z] {
            data.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    w.bytes(&data).bool(true);
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_info_and_images_come_back_as_written() {
        let header = Header { stamp_ns: 1_317_042_272_351_950_336, frame_id: "camera_gray_left".into() };
        let info = CameraInfo {
            header: header.clone(),
            width: 1242,
            height: 375,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [721.5, 0.0, 609.6, 0.0, 721.5, 172.9, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [721.5, 0.0, 609.6, -387.6, 0.0, 721.5, 172.9, 0.0, 0.0, 0.0, 1.0, 0.0],
        };
        assert_eq!(CameraInfo::read(&info.write()).expect("reads"), info);
        let pixels: Vec<u8> = (0..12).collect();
        let msg = write_image(&header, 4, 3, "mono8", 4, &pixels);
        let (h, p) = ImagePayload::read(IMAGE, &msg).expect("reads");
        assert_eq!(h, header);
        assert_eq!(p.describe(), "4×3 mono8");
        assert!(matches!(p, ImagePayload::Raw { step: 4, ref data, .. } if data == &pixels));
        let info = ImageInfo::read(IMAGE, &msg).expect("info");
        assert_eq!(info.raw, Some((4, 3, "mono8".to_string())));
        let msg = write_compressed_image(&header, "png", b"\x89PNG");
        let (_, p) = ImagePayload::read(COMPRESSED_IMAGE, &msg).expect("reads");
        assert_eq!(p, ImagePayload::Compressed { format: "png".into(), data: b"\x89PNG".to_vec() });
        // fewer pixel bytes than the rows need
        let short = write_image(&header, 4, 3, "mono8", 4, &pixels[..8]);
        let e = ImageInfo::read(IMAGE, &short).expect_err("short");
        assert!(e.message.contains("data holds 8 bytes, 3 rows of step 4 need 12"), "{e}");
    }

    #[test]
    fn stamps_keep_their_nanoseconds_and_refuse_a_second_of_them() {
        let h = Header { stamp_ns: -1_500_000_000, frame_id: String::new() };
        let mut w = CdrWriter::new();
        write_header(&mut w, &h);
        assert_eq!(read_header(&w.finish()).expect("reads"), h);
        let mut w = CdrWriter::new();
        w.i32(3).u32(1_000_000_000).string("f");
        assert!(read_header(&w.finish()).expect_err("ns").message.contains("a second or more"));
    }

    #[test]
    fn written_messages_have_the_sizes_their_schemas_give() {
        let pose = Isometry3::translation(1.0, 2.0, 3.0);
        // header (4 + 4 + 4 + "map\0") then 7 float64 aligned to 8
        assert_eq!(path_message(0, "map", &[(0, pose)]).len(), 4 + 16 + 4 + 16 + 4 + 56);
        let cloud = point_cloud_message(0, "map", &[Point3::new(1.0, 2.0, 3.0); 5]);
        assert!(cloud.windows(12).any(|w| w == [0, 0, 128, 63, 0, 0, 0, 64, 0, 0, 64, 64]));
        for (name, text) in output_schemas() {
            assert!(!text.is_empty() && text.contains("MSG: std_msgs/Header"), "{name}");
        }
    }
}
