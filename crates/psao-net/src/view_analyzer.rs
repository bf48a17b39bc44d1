//! The analyzer thread of `psao view --corrective` when the session is not in lockstep
//! (paper §4.4: the analyzer runs at its own rate): the frame loop offers each frame it shows,
//! the analyzer takes one when it is idle and its period has passed since the last one taken,
//! computes the regions on its own thread, and the frame loop picks the result up without
//! waiting. In lockstep (and in `psao run`) the frame loop analyses every `--analyze-every`
//! frames itself, so runs stay deterministic.

use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use psao_wire::RegionsMsg;

use crate::corrective::{CorrectedFrame, FrameAnalysis};
use crate::NetError;

/// The analyzer thread and the frame loop's end of it.
pub(crate) struct Analyzer {
    /// Frames to analyse, tagged with their session (`None` once shutting down).
    frames: Option<SyncSender<(u32, FrameAnalysis)>>,
    /// Finished analyses and their session.
    results: Receiver<(u32, RegionsMsg)>,
    thread: Option<JoinHandle<()>>,
    period: Duration,
    /// When the last frame was taken.
    last: Option<Instant>,
    /// A frame is being analysed.
    busy: bool,
}

impl Analyzer {
    /// Start the thread; it takes a frame at most every `period`.
    pub(crate) fn new(period: Duration) -> Result<Self, NetError> {
        let (frames, inbox) = sync_channel::<(u32, FrameAnalysis)>(1);
        let (outbox, results) = sync_channel::<(u32, RegionsMsg)>(1);
        let thread = std::thread::Builder::new()
            .name("psao-analyzer".into())
            .spawn(move || {
                for (session, frame) in inbox {
                    if outbox.send((session, frame.regions())).is_err() {
                        return;
                    }
                }
            })
            .map_err(NetError::io("cannot start the analyzer thread"))?;
        Ok(Self {
            frames: Some(frames),
            results,
            thread: Some(thread),
            period,
            last: None,
            busy: false,
        })
    }

    /// Offer the frame just shown in `session`: analysed when the analyzer is idle and the
    /// period has passed since the last frame it took; true when taken.
    pub(crate) fn offer(&mut self, session: u32, frame: &CorrectedFrame) -> bool {
        let due = self.last.is_none_or(|t| t.elapsed() >= self.period);
        let Some(frames) = &self.frames else {
            return false;
        };
        if self.busy || !due || frames.try_send((session, frame.analysis())).is_err() {
            return false;
        }
        self.busy = true;
        self.last = Some(Instant::now());
        true
    }

    /// The finished analysis of `session`, if one is ready (analyses of earlier sessions are
    /// dropped).
    pub(crate) fn take(&mut self, session: u32) -> Option<RegionsMsg> {
        let mut found = None;
        loop {
            match self.results.try_recv() {
                Ok((s, regions)) => {
                    self.busy = false;
                    if s == session {
                        found = Some(regions);
                    }
                }
                Err(TryRecvError::Empty) => return found,
                Err(TryRecvError::Disconnected) => {
                    self.busy = false;
                    return found;
                }
            }
        }
    }
}

impl Drop for Analyzer {
    /// Stop the thread after its analysis in flight and join it (at most one analysis is
    /// taken and not yet picked up, so its result never waits for room).
    fn drop(&mut self) {
        self.frames = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corrective::{BaseFrame, CorrectiveClient, CorrectiveClientConfig};
    use glam::Vec3;
    use psao_scene::Camera;

    /// Waits up to 60 s for the analysis of `session`.
    fn wait_for(a: &mut Analyzer, session: u32) -> Option<RegionsMsg> {
        let end = Instant::now() + Duration::from_secs(60);
        while Instant::now() < end {
            if let Some(r) = a.take(session) {
                return Some(r);
            }
            if !a.busy {
                return None;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        None
    }

    #[test]
    fn the_thread_analyses_offered_frames_at_its_own_rate() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(
            &path,
            "[[asset]]\nfile = \"builtin:sphere\"\ntranslation = [0, 0.5, 0]\n\
             [[material]]\nname = \"sphere\"\npreset = \"chrome\"\n",
        )
        .unwrap();
        let scene = psao_scene::scene_file::load(&path).unwrap().scene;
        let (w, h) = (64, 36);
        let camera = Camera::look_at(Vec3::new(0.0, 1.5, 3.5), Vec3::new(0.0, 0.4, 0.0), 60.0);
        let gbuffer =
            psao_raster::rasterize(&scene, &camera, &psao_raster::RasterOptions::new(w, h));
        let ao = vec![1.0; (w * h) as usize];
        let mut client = CorrectiveClient::new(w, h, CorrectiveClientConfig::default()).unwrap();
        client.camera(&crate::convert::camera_msg(0, &camera, w as f32 / h as f32));
        // The frame loop's own analysis of frame 0 is the reference.
        let expected = client
            .frame(&scene, 0, &gbuffer, BaseFrame::Ao(&ao))
            .regions
            .unwrap();
        assert!(!expected.regions.is_empty());
        let shown = client.correct(&scene, 0, &gbuffer, BaseFrame::Ao(&ao));
        assert!(shown.regions.is_none());

        let period = Duration::from_millis(200);
        let mut a = Analyzer::new(period).unwrap();
        let t = Instant::now();
        assert!(a.offer(1, &shown));
        // Busy, and within the period: later frames are not taken.
        assert!(!a.offer(1, &shown));
        assert_eq!(wait_for(&mut a, 1), Some(expected.clone()));
        if t.elapsed() < period {
            assert!(!a.offer(1, &shown));
        }
        std::thread::sleep(period);
        // An analysis of an earlier session is dropped, and frees the analyzer.
        assert!(a.offer(1, &shown));
        assert_eq!(wait_for(&mut a, 2), None);
        std::thread::sleep(period);
        assert!(a.offer(2, &shown));
        assert_eq!(wait_for(&mut a, 2), Some(expected));
        // Dropping a busy analyzer joins its thread.
        std::thread::sleep(period);
        assert!(a.offer(2, &shown));
        drop(a);
    }
}
