//! Frames to an MP4 file that browsers play: H.264 (Cisco's OpenH264) in an MP4 container (the
//! `mp4` crate), one sample per frame. OpenH264 writes Annex B (start codes); MP4 keeps the
//! sequence and picture parameter sets in the track's `avcC` box and each frame's other NAL
//! units prefixed by their length.

use anyhow::{Context, Result, anyhow, bail};
use openh264::encoder::{Encoder, EncoderConfig, FrameRate, QpRange, RateControlMode};
use openh264::formats::{RgbSliceU8, YUVBuffer};
use splat_runtime::Image;
use std::io::Cursor;

/// H.264's quantizer (0 to 51, lower is finer): 20 keeps a render's stars and edges (about
/// 1% mean error on the built-in scene).
const QUANTIZER: u8 = 20;

/// The MP4 track's clock: ticks per second.
const TIMESCALE: u32 = 90_000;

/// An MP4 being written in memory, frame by frame.
pub struct Video {
    encoder: Encoder,
    width: u32,
    height: u32,
    /// Ticks per frame.
    tick: u32,
    /// The parameter sets, from the first frame.
    sps: Vec<u8>,
    pps: Vec<u8>,
    /// Each frame: its NAL units length-prefixed, and whether it is a key frame.
    samples: Vec<(Vec<u8>, bool)>,
}

impl Video {
    /// A video of `width` x `height` frames (even sizes: H.264 stores color at half
    /// resolution) at `fps` frames per second.
    pub fn new(width: u32, height: u32, fps: u32) -> Result<Video> {
        if !width.is_multiple_of(2) || !height.is_multiple_of(2) || width < 16 || height < 16 {
            bail!(
                "a video's frames are even sizes of at least 16x16 (H.264 stores color at half resolution): {width}x{height} is not"
            );
        }
        if !(1..=240).contains(&fps) {
            bail!("{fps} frames per second: give 1 to 240");
        }
        // A constant quantizer, no rate control: every frame as sharp as the next, none skipped.
        let config = EncoderConfig::new()
            .max_frame_rate(FrameRate::from_hz(fps as f32))
            .rate_control_mode(RateControlMode::Off)
            .qp(QpRange::new(QUANTIZER, QUANTIZER))
            .skip_frames(false);
        let api = openh264::OpenH264API::from_source();
        let encoder =
            Encoder::with_api_config(api, config).map_err(|e| anyhow!("H.264 encoder: {e}"))?;
        Ok(Video {
            encoder,
            width,
            height,
            tick: TIMESCALE / fps,
            sps: vec![],
            pps: vec![],
            samples: vec![],
        })
    }

    pub fn frames(&self) -> usize {
        self.samples.len()
    }

    /// Encodes the next frame (RGB in [0, 1], the video's size).
    pub fn push(&mut self, image: &Image) -> Result<()> {
        if (image.width, image.height, image.channels) != (self.width, self.height, 3) {
            bail!(
                "a {}x{} frame for a {}x{} video",
                image.width,
                image.height,
                self.width,
                self.height
            );
        }
        let rgb: Vec<u8> = (image.data.iter())
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let size = (self.width as usize, self.height as usize);
        let yuv = YUVBuffer::from_rgb_source(RgbSliceU8::new(&rgb, size));
        let stream = self
            .encoder
            .encode(&yuv)
            .map_err(|e| anyhow!("H.264: {e}"))?;
        let (mut sample, mut key) = (vec![], false);
        for l in 0..stream.num_layers() {
            let layer = stream.layer(l).expect("a layer below the count");
            for n in 0..layer.nal_count() {
                let nal = strip_start_code(layer.nal_unit(n).expect("a NAL unit below the count"));
                match nal.first().map(|b| b & 0x1f) {
                    Some(7) => self.sps = nal.to_vec(),
                    Some(8) => self.pps = nal.to_vec(),
                    Some(kind) => {
                        key |= kind == 5;
                        sample.extend_from_slice(&(nal.len() as u32).to_be_bytes());
                        sample.extend_from_slice(nal);
                    }
                    None => {}
                }
            }
        }
        if sample.is_empty() {
            bail!("the H.264 encoder skipped frame {}", self.samples.len());
        }
        self.samples.push((sample, key));
        Ok(())
    }

    /// The MP4 file's bytes.
    pub fn finish(self) -> Result<Vec<u8>> {
        if self.samples.is_empty() || self.sps.is_empty() || self.pps.is_empty() {
            bail!("a video needs at least one frame");
        }
        let config = mp4::Mp4Config {
            major_brand: str::parse("isom")?,
            minor_version: 512,
            compatible_brands: ["isom", "iso2", "avc1", "mp41"]
                .iter()
                .map(|b| str::parse(b))
                .collect::<Result<_, _>>()?,
            timescale: TIMESCALE,
        };
        let mut mp4 = mp4::Mp4Writer::write_start(Cursor::new(Vec::new()), &config)?;
        mp4.add_track(&mp4::TrackConfig {
            track_type: mp4::TrackType::Video,
            timescale: TIMESCALE,
            language: "und".to_string(),
            media_conf: mp4::MediaConfig::AvcConfig(mp4::AvcConfig {
                width: self.width.try_into().context("a video wider than 65535")?,
                height: self
                    .height
                    .try_into()
                    .context("a video taller than 65535")?,
                seq_param_set: self.sps,
                pic_param_set: self.pps,
            }),
        })?;
        for (k, (bytes, key)) in self.samples.into_iter().enumerate() {
            let sample = mp4::Mp4Sample {
                start_time: k as u64 * self.tick as u64,
                duration: self.tick,
                rendering_offset: 0,
                is_sync: key,
                bytes: bytes.into(),
            };
            mp4.write_sample(1, &sample)?;
        }
        mp4.write_end()?;
        Ok(mp4.into_writer().into_inner())
    }
}

/// A NAL unit without the Annex B start code before it (00 00 01 or 00 00 00 01).
fn strip_start_code(nal: &[u8]) -> &[u8] {
    let zeros = nal.iter().take_while(|b| **b == 0).count();
    match nal.get(zeros) {
        Some(1) if zeros >= 2 => &nal[zeros + 1..],
        _ => nal,
    }
}
