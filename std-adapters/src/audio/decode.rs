//! Decoding to interleaved f32: hound for WAV, symphonia for the rest.

use std::fs::File;
use std::path::Path;

use symphonia::core::audio::SampleBuffer;
use symphonia::core::codecs::{DecoderOptions, CODEC_TYPE_NULL};
use symphonia::core::errors::Error as SymError;
use symphonia::core::formats::FormatOptions;
use symphonia::core::io::MediaSourceStream;
use symphonia::core::meta::MetadataOptions;
use symphonia::core::probe::Hint;

use super::AudioError;

/// Decoded audio: interleaved samples in [-1, 1].
#[derive(Debug, Clone)]
pub struct Decoded {
    pub sample_rate: u32,
    pub channels: usize,
    /// (frames, channels) interleaved.
    pub samples: Vec<f32>,
}

impl Decoded {
    /// Channel average (essentia MonoLoader's downmix).
    pub fn mono(&self) -> Vec<f32> {
        if self.channels == 1 {
            return self.samples.clone();
        }
        let inv = 1.0 / self.channels as f32;
        self.samples
            .chunks_exact(self.channels)
            .map(|f| f.iter().sum::<f32>() * inv)
            .collect()
    }
}

/// Decodes a WAV, MP3, OGG Vorbis or FLAC file (chosen by content, the extension as a hint).
pub fn decode(path: &Path) -> Result<Decoded, AudioError> {
    let is_wav = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("wav"));
    let d = if is_wav {
        decode_wav(path)?
    } else {
        decode_symphonia(path)?
    };
    if d.sample_rate == 0 {
        return Err(AudioError::BadRate {
            path: path.to_path_buf(),
            rate: 0,
        });
    }
    if d.channels == 0 || d.channels > 32 {
        return Err(AudioError::BadChannels {
            path: path.to_path_buf(),
            channels: d.channels,
        });
    }
    Ok(d)
}

fn decode_wav(path: &Path) -> Result<Decoded, AudioError> {
    let wav_err = |e: hound::Error| match e {
        hound::Error::IoError(error) if error.kind() == std::io::ErrorKind::NotFound => {
            AudioError::Io {
                path: path.to_path_buf(),
                error,
            }
        }
        other => AudioError::Wav {
            path: path.to_path_buf(),
            reason: other.to_string(),
        },
    };
    let reader = hound::WavReader::open(path).map_err(wav_err)?;
    let spec = reader.spec();
    let channels = spec.channels as usize;
    if channels == 0 {
        return Err(AudioError::BadChannels {
            path: path.to_path_buf(),
            channels,
        });
    }
    let samples: Result<Vec<f32>, hound::Error> = match spec.sample_format {
        hound::SampleFormat::Float => reader.into_samples::<f32>().collect(),
        hound::SampleFormat::Int => {
            if spec.bits_per_sample == 0 || spec.bits_per_sample > 32 {
                return Err(AudioError::Wav {
                    path: path.to_path_buf(),
                    reason: format!("{} bits per sample (expected 8..=32)", spec.bits_per_sample),
                });
            }
            let scale = 1.0 / (1u64 << (spec.bits_per_sample - 1)) as f32;
            reader
                .into_samples::<i32>()
                .map(|s| s.map(|v| v as f32 * scale))
                .collect()
        }
    };
    let mut samples = samples.map_err(wav_err)?;
    samples.truncate(samples.len() / channels * channels);
    Ok(Decoded {
        sample_rate: spec.sample_rate,
        channels,
        samples,
    })
}

fn decode_symphonia(path: &Path) -> Result<Decoded, AudioError> {
    let fmt_err = |e: SymError| AudioError::Format {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let file = File::open(path).map_err(|error| AudioError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let mss = MediaSourceStream::new(Box::new(file), Default::default());
    let mut hint = Hint::new();
    if let Some(ext) = path.extension().and_then(|e| e.to_str()) {
        hint.with_extension(ext);
    }
    // enable_gapless: trims MP3 encoder delay/padding (LAME/Xing) and Vorbis/FLAC priming.
    let fmt_opts = FormatOptions {
        enable_gapless: true,
        ..Default::default()
    };
    let probed = symphonia::default::get_probe()
        .format(&hint, mss, &fmt_opts, &MetadataOptions::default())
        .map_err(fmt_err)?;
    let mut format = probed.format;
    let track = format
        .tracks()
        .iter()
        .find(|t| t.codec_params.codec != CODEC_TYPE_NULL)
        .ok_or_else(|| AudioError::NoTrack {
            path: path.to_path_buf(),
        })?;
    let track_id = track.id;
    let mut sample_rate = track.codec_params.sample_rate.unwrap_or(0);
    let mut channels = track.codec_params.channels.map_or(0, |c| c.count());
    let mut decoder = symphonia::default::get_codecs()
        .make(&track.codec_params, &DecoderOptions::default())
        .map_err(fmt_err)?;
    let mut samples = Vec::new();
    let mut buf: Option<SampleBuffer<f32>> = None;
    loop {
        let packet = match format.next_packet() {
            Ok(p) => p,
            Err(SymError::IoError(e)) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(SymError::ResetRequired) => break,
            Err(e) => return Err(fmt_err(e)),
        };
        if packet.track_id() != track_id {
            continue;
        }
        match decoder.decode(&packet) {
            Ok(audio) => {
                let spec = *audio.spec();
                sample_rate = spec.rate;
                channels = spec.channels.count();
                let need = audio.capacity() as u64;
                if buf
                    .as_ref()
                    .is_none_or(|b| b.capacity() < need as usize * channels)
                {
                    buf = Some(SampleBuffer::new(need, spec));
                }
                let b = buf.as_mut().expect("just set");
                b.copy_interleaved_ref(audio);
                samples.extend_from_slice(b.samples());
            }
            // a corrupt frame: skip it like players do
            Err(SymError::DecodeError(_)) => continue,
            Err(e) => return Err(fmt_err(e)),
        }
    }
    if channels == 0 {
        return Err(AudioError::BadChannels {
            path: path.to_path_buf(),
            channels,
        });
    }
    Ok(Decoded {
        sample_rate,
        channels,
        samples,
    })
}
