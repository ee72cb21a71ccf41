import AVFoundation
import Monotrack
import SwiftUI

/// Owns the capture session and the tracker, a video-mode `FaceTracker` (built on `frameQueue`,
/// which is also the only queue that reads it). Frames arrive on `frameQueue` (a serial queue), are
/// tracked there synchronously at their presentation time and the results are published on the
/// main queue. Late frames are dropped (`alwaysDiscardsLateVideoFrames`), so a slow frame costs
/// frames, not latency. The record switch writes what the tracker is given to
/// `Documents/recordings/` (on `frameQueue`, between frames), for `monotrack replay` on a desktop.
final class CameraModel: NSObject, ObservableObject, AVCaptureVideoDataOutputSampleBufferDelegate {
    @Published private(set) var result: TrackingResult?
    @Published private(set) var fps: Double = 0
    @Published private(set) var message: String?
    @Published private(set) var previewRotationAngle: CGFloat = 90
    @Published private(set) var isRecording = false

    /// A recording's limit: about half a minute of 640×480 NV12 frames at 30 fps.
    private static let maxRecordingBytes: UInt64 = 512 << 20

    let session = AVCaptureSession()
    private let frameQueue = DispatchQueue(label: "io.monotrack.sample.frames")
    private var tracker: FaceTracker?
    private var coordinator: AVCaptureDevice.RotationCoordinator?
    private var observations: [NSKeyValueObservation] = []
    private var isFront = true

    // Written on the main queue by KVO, read on frameQueue.
    private let angleLock = NSLock()
    private var captureAngle: CGFloat = 90

    private var lastFrameTime: CFTimeInterval = 0
    private var meanInterval: Double = 0

    /// Weight of the newest frame interval in the fps average: about a 10-frame memory.
    private static let fpsSmoothing = 0.1

    @MainActor
    func start() async {
        guard await AVCaptureDevice.requestAccess(for: .video) else {
            message = "Camera access is off: enable it in Settings to track your face."
            return
        }
        let intrinsics: CameraIntrinsics?
        do {
            intrinsics = try configureSession()
        } catch {
            message = "Could not start: \(error)"
            return
        }
        // Loading the models takes a while: on the frame queue, never the main thread. Frames that
        // arrive before it is done find no tracker and are skipped.
        frameQueue.async { [weak self, session] in
            var options = FaceTrackerOptions(runningMode: .video)
            options.camera = intrinsics
            do {
                self?.tracker = try FaceTracker(options: options)
            } catch {
                DispatchQueue.main.async { self?.message = "Could not load the tracker: \(error)" }
                return
            }
            session.startRunning()
        }
    }

    func stop() {
        frameQueue.async { [weak self, session] in
            session.stopRunning()
            // A restarted camera begins new tracks; its clock may also start over.
            self?.tracker?.reset()
        }
    }

    /// Starts a recording into a new file of `Documents/recordings/`, or stops the one running.
    func setRecording(_ on: Bool) {
        frameQueue.async { [weak self] in
            guard let self, let tracker = self.tracker else { return }
            let note: String
            do {
                if on && !tracker.isRecording() {
                    let dir = try FileManager.default.url(for: .documentDirectory, in: .userDomainMask,
                                                          appropriateFor: nil, create: true)
                        .appendingPathComponent("recordings", isDirectory: true)
                    try FileManager.default.createDirectory(at: dir, withIntermediateDirectories: true)
                    let file = dir.appendingPathComponent("monotrack-\(Int(Date().timeIntervalSince1970)).mtrec")
                    try tracker.startRecording(path: file.path, maxBytes: Self.maxRecordingBytes)
                    note = "Recording to \(file.lastPathComponent)"
                } else if !on && tracker.isRecording() {
                    let s = try tracker.stopRecording()
                    let mb = Double(s.bytes) / 1e6
                    note = String(format: "Recorded %llu frames (%.1f MB)", s.frames, mb)
                        + (s.truncated ? ", stopped at the size limit" : "")
                } else {
                    return
                }
            } catch {
                note = "Recording failed: \(error)"
            }
            let recording = tracker.isRecording()
            DispatchQueue.main.async {
                self.isRecording = recording
                self.message = note
            }
        }
    }

    /// Sets up the session; returns the intrinsics of the 640×480 buffers the camera will deliver
    /// (from the format's field of view), or `nil` to leave the SDK's default.
    @MainActor
    private func configureSession() throws -> CameraIntrinsics? {
        let device = AVCaptureDevice.default(.builtInWideAngleCamera, for: .video, position: .front)
            ?? AVCaptureDevice.default(for: .video)
        guard let device else { throw FrameError.invalidLayout("no camera") }
        isFront = device.position == .front

        session.beginConfiguration()
        defer { session.commitConfiguration() }
        // 640x480 is plenty for faces at arm's length and keeps each frame cheap.
        if session.canSetSessionPreset(.vga640x480) { session.sessionPreset = .vga640x480 }
        let input = try AVCaptureDeviceInput(device: device)
        guard session.canAddInput(input) else { throw FrameError.invalidLayout("camera input refused") }
        session.addInput(input)

        let output = AVCaptureVideoDataOutput()
        // NV12 full range, the camera's native format: the tracker reads its luma plane in place.
        output.videoSettings = [kCVPixelBufferPixelFormatTypeKey as String: kCVPixelFormatType_420YpCbCr8BiPlanarFullRange]
        output.alwaysDiscardsLateVideoFrames = true
        output.setSampleBufferDelegate(self, queue: frameQueue)
        guard session.canAddOutput(output) else { throw FrameError.invalidLayout("video output refused") }
        session.addOutput(output)
        let intrinsics = CameraIntrinsics(fieldOfViewDegrees: Double(device.activeFormat.videoFieldOfView),
                                          width: 640, height: 480)
        // The connection is left unrotated: the SDK rotates while converting, which avoids a copy.

        let coordinator = AVCaptureDevice.RotationCoordinator(device: device, previewLayer: nil)
        self.coordinator = coordinator
        setCaptureAngle(coordinator.videoRotationAngleForHorizonLevelCapture)
        previewRotationAngle = coordinator.videoRotationAngleForHorizonLevelPreview
        observations = [
            coordinator.observe(\.videoRotationAngleForHorizonLevelCapture, options: [.new]) { [weak self] c, _ in
                self?.setCaptureAngle(c.videoRotationAngleForHorizonLevelCapture)
            },
            coordinator.observe(\.videoRotationAngleForHorizonLevelPreview, options: [.new]) { [weak self] c, _ in
                let angle = c.videoRotationAngleForHorizonLevelPreview
                DispatchQueue.main.async { self?.previewRotationAngle = angle }
            },
        ]
        return intrinsics
    }

    private func setCaptureAngle(_ angle: CGFloat) {
        angleLock.lock()
        captureAngle = angle
        angleLock.unlock()
    }

    func captureOutput(_ output: AVCaptureOutput, didOutput sampleBuffer: CMSampleBuffer, from connection: AVCaptureConnection) {
        guard let tracker else { return }
        angleLock.lock()
        let angle = captureAngle
        angleLock.unlock()
        do {
            let orientation = try FrameOrientation(videoRotationAngle: angle, frontCamera: isFront)
            let result = try tracker.detectForVideo(sampleBuffer, orientation: orientation)
            let rate = tick()
            DispatchQueue.main.async {
                self.result = result
                self.fps = rate
            }
        } catch {
            // A bad frame is skipped; the next one is tracked (or re-detected) as usual.
            DispatchQueue.main.async { self.message = "\(error)" }
        }
    }

    private func tick() -> Double {
        let now = CACurrentMediaTime()
        defer { lastFrameTime = now }
        guard lastFrameTime > 0 else { return 0 }
        let dt = now - lastFrameTime
        meanInterval = meanInterval == 0 ? dt : meanInterval + Self.fpsSmoothing * (dt - meanInterval)
        return meanInterval > 0 ? 1 / meanInterval : 0
    }
}
