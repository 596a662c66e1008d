//! Decoders for the ROS messages tumble reads, in both wire formats: ROS 1
//! serialization (packed little-endian, `Header` with a `seq`) and ROS 2 CDR
//! (little-endian encapsulation, each primitive aligned to its size from the
//! end of the 4-byte encapsulation header, `Header` without `seq`).
//!
//! Every decoder returns `None` for a buffer too short or not little-endian
//! CDR; callers name the message in their error.

/// How a message's bytes are laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 1 serialization (bags `.bag`).
    Ros1,
    /// ROS 2 CDR with its 4-byte encapsulation header (`.db3`, `.mcap`).
    Cdr,
}

/// Little-endian reader over one message.
struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
    origin: usize,
    align: bool,
}

impl<'a> Reader<'a> {
    /// A reader positioned after the encapsulation header (CDR, little-endian only).
    fn new(enc: Encoding, b: &'a [u8]) -> Option<Reader<'a>> {
        match enc {
            Encoding::Ros1 => Some(Reader { b, pos: 0, origin: 0, align: false }),
            Encoding::Cdr => (b.len() >= 4 && b[1] == 0x01).then_some(Reader { b, pos: 4, origin: 4, align: true }),
        }
    }
    fn take(&mut self, n: usize, align: usize) -> Option<&'a [u8]> {
        if self.align && align > 1 {
            let rel = self.pos - self.origin;
            self.pos += (align - rel % align) % align;
        }
        let s = self.b.get(self.pos..self.pos.checked_add(n)?)?;
        self.pos += n;
        Some(s)
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.take(1, 1)?[0])
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4, 4)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8, 8)?.try_into().ok()?))
    }
    /// A byte sequence: u32 length, then the bytes (strings carry their NUL in CDR).
    fn bytes(&mut self) -> Option<&'a [u8]> {
        let n = self.u32()? as usize;
        self.take(n, 1)
    }
    fn string(&mut self) -> Option<String> {
        let b = self.bytes()?;
        let b = b.strip_suffix(&[0]).unwrap_or(b);
        Some(String::from_utf8_lossy(b).into_owned())
    }
    fn vec3(&mut self) -> Option<[f64; 3]> {
        Some([self.f64()?, self.f64()?, self.f64()?])
    }
    /// A quaternion as stored (x, y, z, w), returned as (w, x, y, z).
    fn quat_wxyz(&mut self) -> Option<[f64; 4]> {
        let [x, y, z] = self.vec3()?;
        Some([self.f64()?, x, y, z])
    }
    fn skip_f64(&mut self, n: usize) -> Option<()> {
        for _ in 0..n {
            self.f64()?;
        }
        Some(())
    }
    /// `std_msgs/Header`: the stamp \[ns\] and the frame id.
    fn header(&mut self) -> Option<(i64, String)> {
        if !self.align {
            self.u32()?; // ROS 1 seq
        }
        // ROS 1 time is two u32; ROS 2 builtin_interfaces/Time is (i32 sec, u32 nanosec).
        let sec = self.u32()?;
        let sec = if self.align { i64::from(sec as i32) } else { i64::from(sec) };
        let nsec = i64::from(self.u32()?);
        let frame = self.string()?;
        Some((sec * 1_000_000_000 + nsec, frame))
    }
}

/// `sensor_msgs/Imu`: stamp \[ns\], angular velocity \[rad/s\], linear acceleration \[m/s²\].
pub fn imu(enc: Encoding, b: &[u8]) -> Option<(i64, [f64; 3], [f64; 3])> {
    let mut r = Reader::new(enc, b)?;
    let (t, _) = r.header()?;
    r.skip_f64(4 + 9)?; // orientation, covariance
    let w = r.vec3()?;
    r.skip_f64(9)?;
    let a = r.vec3()?;
    Some((t, w, a))
}

/// `sensor_msgs/Temperature`: stamp \[ns\] and temperature \[°C\].
pub fn temperature(enc: Encoding, b: &[u8]) -> Option<(i64, f64)> {
    let mut r = Reader::new(enc, b)?;
    let (t, _) = r.header()?;
    Some((t, r.f64()?))
}

/// A `sensor_msgs/Image`, its pixels borrowed from the message.
#[derive(Debug, Clone)]
pub struct Image<'a> {
    /// Stamp \[ns\].
    pub t_ns: i64,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`mono8`, `mono16`, `rgb8`, `bgr8`, `rgba8`, `bgra8`, …).
    pub encoding: String,
    /// Multi-byte pixels stored big-endian.
    pub big_endian: bool,
    /// Bytes per row.
    pub step: u32,
    /// `step · height` bytes.
    pub data: &'a [u8],
}

/// `sensor_msgs/Image`.
pub fn image(enc: Encoding, b: &[u8]) -> Option<Image<'_>> {
    let mut r = Reader::new(enc, b)?;
    let (t_ns, _) = r.header()?;
    let height = r.u32()?;
    let width = r.u32()?;
    let encoding = r.string()?;
    let big_endian = r.u8()? != 0;
    let step = r.u32()?;
    let data = r.bytes()?;
    Some(Image { t_ns, height, width, encoding, big_endian, step, data })
}

/// `sensor_msgs/CompressedImage`: stamp \[ns\], format (`jpeg`, `png`, or
/// `mono8; png compressed …`), and the compressed bytes.
pub fn compressed_image(enc: Encoding, b: &[u8]) -> Option<(i64, String, &[u8])> {
    let mut r = Reader::new(enc, b)?;
    let (t, _) = r.header()?;
    let format = r.string()?;
    Some((t, format, r.bytes()?))
}

/// The intrinsics of a `sensor_msgs/CameraInfo`.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraInfo {
    /// Columns \[px\].
    pub width: u32,
    /// Rows \[px\].
    pub height: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`, …
    pub distortion_model: String,
    /// Distortion coefficients in the model's order.
    pub d: Vec<f64>,
    /// Camera matrix, row-major \[px\].
    pub k: [f64; 9],
}

/// `sensor_msgs/CameraInfo`.
pub fn camera_info(enc: Encoding, b: &[u8]) -> Option<CameraInfo> {
    let mut r = Reader::new(enc, b)?;
    r.header()?;
    let height = r.u32()?;
    let width = r.u32()?;
    let distortion_model = r.string()?;
    let n = r.u32()? as usize;
    if n > 64 {
        return None; // no distortion model has that many coefficients: not a CameraInfo
    }
    let d = (0..n).map(|_| r.f64()).collect::<Option<Vec<_>>>()?;
    let mut k = [0.0; 9];
    for v in &mut k {
        *v = r.f64()?;
    }
    Some(CameraInfo { width, height, distortion_model, d, k })
}

/// A stamped pose: stamp \[ns\], position \[m\] and orientation (w, x, y, z)
/// of the child (body) frame in the parent frame.
pub type StampedPose = (i64, [f64; 3], [f64; 4]);

/// Ground-truth poses from `geometry_msgs/PoseStamped`,
/// `geometry_msgs/PoseWithCovarianceStamped`, `geometry_msgs/TransformStamped`
/// or `nav_msgs/Odometry` (`msg_type` as [`super::normalize_type`] gives it).
pub fn pose(msg_type: &str, enc: Encoding, b: &[u8]) -> Option<StampedPose> {
    let mut r = Reader::new(enc, b)?;
    let (t, _) = r.header()?;
    match msg_type {
        "geometry_msgs/PoseStamped" | "geometry_msgs/PoseWithCovarianceStamped" => {}
        "geometry_msgs/TransformStamped" | "nav_msgs/Odometry" => {
            r.string()?; // child_frame_id
        }
        _ => return None,
    }
    let p = r.vec3()?;
    let q = r.quat_wxyz()?;
    Some((t, p, q))
}

/// The message types [`pose`] decodes.
pub const POSE_TYPES: [&str; 4] = [
    "geometry_msgs/PoseStamped",
    "geometry_msgs/PoseWithCovarianceStamped",
    "geometry_msgs/TransformStamped",
    "nav_msgs/Odometry",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_alignment_after_an_odd_frame_id() {
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(5i32.to_le_bytes());
        b.extend(7u32.to_le_bytes());
        b.extend(4u32.to_le_bytes());
        b.extend(b"imu\0");
        // Now at offset 16 from the origin: already 8-aligned.
        for v in (0..13).map(|_| 0.0f64).chain([0.1, 0.2, 0.3]).chain((0..9).map(|_| 0.0)).chain([1.0, 2.0, 9.8]) {
            b.extend(v.to_le_bytes());
        }
        let (t, w, a) = imu(Encoding::Cdr, &b).unwrap();
        assert_eq!((t, w, a), (5_000_000_007, [0.1, 0.2, 0.3], [1.0, 2.0, 9.8]));
        assert!(imu(Encoding::Cdr, &b[..b.len() - 1]).is_none());
        b[1] = 0; // big-endian CDR is not decoded
        assert!(imu(Encoding::Cdr, &b).is_none());
    }

    #[test]
    fn cdr_image_and_temperature() {
        // Header with a 2-byte frame id ("c\0"): the f64 after it pads to 8.
        let mut b = vec![0u8, 1, 0, 0];
        b.extend(1i32.to_le_bytes());
        b.extend(2u32.to_le_bytes());
        b.extend(2u32.to_le_bytes());
        b.extend(b"c\0");
        let head = b.clone();
        b.extend([0u8; 2]); // f64 aligns to 8
        b.extend(36.5f64.to_le_bytes());
        assert_eq!(temperature(Encoding::Cdr, &b), Some((1_000_000_002, 36.5)));
        let mut im = head;
        im.extend([0u8; 2]); // u32 height aligns to 4
        im.extend(2u32.to_le_bytes());
        im.extend(3u32.to_le_bytes());
        im.extend(6u32.to_le_bytes());
        im.extend(b"mono8\0");
        im.push(0); // is_bigendian
        im.extend([0u8; 1]); // step aligns to 4
        im.extend(3u32.to_le_bytes());
        im.extend(6u32.to_le_bytes());
        im.extend([1, 2, 3, 4, 5, 6]);
        let i = image(Encoding::Cdr, &im).unwrap();
        assert_eq!(
            (i.height, i.width, i.encoding.as_str(), i.step, i.data),
            (2, 3, "mono8", 3, &[1u8, 2, 3, 4, 5, 6][..])
        );
    }
}
