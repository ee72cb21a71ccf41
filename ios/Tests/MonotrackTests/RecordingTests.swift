// Recording through the generated bindings (the port of bindings/tests/kotlin/RecordingTest.kt): a
// video tracker and a live stream record NV21 frames of the sample face (a phone's sensor buffers,
// turned by 90°) to files, which bindings/tests/run-swift.sh then replays with `monotrack replay`
// (every frame must be identical); the recorder's typed errors and its size limit.
import Foundation
import XCTest
@testable import Monotrack

/// Where the recordings go: $MONOTRACK_RECORDINGS (run-swift.sh replays from there), else the
/// temporary folder.
private let recordings: URL = {
    let env = ProcessInfo.processInfo.environment["MONOTRACK_RECORDINGS"] ?? ""
    let dir = env.isEmpty ? FileManager.default.temporaryDirectory : URL(fileURLWithPath: env)
    try? FileManager.default.createDirectory(at: dir, withIntermediateDirectories: true)
    return dir
}()

/// Frame `i` of a clip of the sample face moving right by 6 px a frame, as the NV21 buffer of a
/// sensor mounted at 90° (rows padded, chroma grey): the frame's rotation 90 makes it upright.
private struct Clip {
    let w: Int
    let h: Int
    let luma: [UInt8]

    init() throws {
        let img = try sample()
        (w, h) = (img.width, img.height)
        var l = [UInt8](repeating: 0, count: img.width * img.height)
        for y in 0..<img.height { for x in 0..<img.width { l[y * img.width + x] = img.luma(x, y) } }
        luma = l
    }

    /// The sensor buffer is h wide and w high; its pixel (x, y) is the upright (w - 1 - y, x).
    var desc: FrameDesc {
        FrameDesc(width: UInt32(h), height: UInt32(w), format: .nv21, rowStride: UInt32(h + pad),
                  uvRowStride: UInt32(h + pad), uvPixelStride: 2, rotationDegrees: 90, mirrored: false)
    }

    func frame(_ i: Int) -> Data {
        let stride = h + pad
        var b = [UInt8](repeating: 128, count: stride * w + stride * ((w + 1) / 2))
        for y in 0..<w {
            let ux = w - 1 - y - 6 * i
            guard (0..<w).contains(ux) else { continue }
            for x in 0..<h { b[y * stride + x] = luma[x * w + ux] }
        }
        return Data(b)
    }
}

/// Counts the live stream's deliveries and signals the one of `until`.
private final class Deliveries: LiveStreamListener, @unchecked Sendable {
    private let lock = NSLock()
    private var results: [(faces: Int, dropped: UInt64)] = []
    private var errors: [String] = []
    private let until: Int64
    let arrived = DispatchSemaphore(value: 0)

    init(until: Int64) { self.until = until }

    var snapshot: (results: [(faces: Int, dropped: UInt64)], errors: [String]) {
        lock.lock(); defer { lock.unlock() }
        return (results, errors)
    }

    func onResult(result: LiveStreamResult) {
        lock.lock()
        results.append((result.result.faces.count, result.framesDropped))
        lock.unlock()
        if result.timestampMs == until { arrived.signal() }
    }

    func onError(timestampMs: Int64, framesDropped: UInt64, error: MonotrackError) {
        lock.lock()
        errors.append("\(timestampMs) ms: \(error)")
        lock.unlock()
    }
}

private func fileSize(_ url: URL) throws -> UInt64 {
    let attrs = try FileManager.default.attributesOfItem(atPath: url.path)
    return (attrs[.size] as? NSNumber)?.uint64Value ?? 0
}

final class RecordingTests: XCTestCase {
    func testAVideoTrackerRecordsItsFramesTargetsAndTaps() throws {
        let clip = try Clip()
        let file = recordings.appendingPathComponent("swift-video.mtrec")
        let t = try FaceTracker(options: options(.video))
        XCTAssertFalse(t.isRecording())
        assertInvalidState(try t.stopRecording(), "nothing is recording")
        try t.setGazeTargets(targets: [screenTarget(id: "phone", widthMm: 70, heightMm: 150, cameraRightMm: 35, cameraDownMm: -8)])
        _ = try t.detectForVideo(bytes: clip.frame(0), desc: clip.desc, timestampMs: 0)
        try t.startRecording(path: file.path, maxBytes: 64 << 20)
        XCTAssertTrue(t.isRecording())
        assertInvalidState(try t.startRecording(path: file.path, maxBytes: 64 << 20), "a recording runs")
        for i in 1...5 {
            let r = try t.detectForVideo(bytes: clip.frame(i), desc: clip.desc, timestampMs: Int64(33 * i))
            XCTAssertEqual(r.faces.count, 1, "frame \(i)")
            if i == 3 {
                XCTAssertEqual(try t.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 35, vMm: 50),
                                                         timestampMs: Int64(33 * i)), 1)
            }
        }
        let s = try t.stopRecording()
        XCTAssertFalse(t.isRecording())
        XCTAssertEqual(s.frames, 5)
        XCTAssertEqual(s.droppedFrames, 0)
        XCTAssertFalse(s.truncated)
        XCTAssertEqual(s.bytes, try fileSize(file))
    }

    func testALiveStreamRecordsTheFramesItTookAndNotesItsDrops() throws {
        let clip = try Clip()
        let file = recordings.appendingPathComponent("swift-live.mtrec")
        let submitted = 8
        let deliveries = Deliveries(until: Int64(33 * submitted))
        let frames = (1...submitted).map { clip.frame($0) }
        let t = try FaceTracker(options: options(.liveStream), listener: deliveries)
        try t.startRecording(path: file.path, maxBytes: 64 << 20)
        for i in 1...submitted {
            _ = try t.detectAsync(bytes: frames[i - 1], desc: clip.desc, timestampMs: Int64(33 * i))
            usleep(20_000) // faster than the worker: it takes some frames and drops others
        }
        XCTAssertEqual(deliveries.arrived.wait(timeout: .now() + 120), .success, "the newest frame is always delivered")
        let s = try t.stopRecording()
        t.shutdown()
        let (results, errors) = deliveries.snapshot
        XCTAssertEqual(errors, [])
        XCTAssertTrue(results.allSatisfy { $0.faces == 1 }, "every delivery found the face")
        XCTAssertEqual(s.frames, UInt64(results.count), "the frames the worker took")
        XCTAssertEqual(s.droppedFrames, results.map(\.dropped).reduce(0, +))
        XCTAssertEqual(s.frames + s.droppedFrames, UInt64(submitted))
        XCTAssertGreaterThanOrEqual(s.frames, 2, "the first frame and the last are taken")
        XCTAssertEqual(s.bytes, try fileSize(file))
    }

    func testARecordingStopsAtItsSizeLimitAndBadPathsAreTyped() throws {
        let clip = try Clip()
        let file = recordings.appendingPathComponent("swift-small.mtrec")
        let t = try FaceTracker(options: options(.video))
        do {
            try t.startRecording(path: "/nonexistent-dir/x.mtrec", maxBytes: 1 << 20)
            XCTFail("no error for a path that cannot be created")
        } catch MonotrackError.Io {
        } catch {
            XCTFail("\(error): expected Io")
        }
        assertInvalidConfig(try t.startRecording(path: file.path, maxBytes: 100), "no room for the settings")
        // Room for the settings and about one frame.
        let oneFrame = UInt64(clip.frame(0).count)
        try t.startRecording(path: file.path, maxBytes: oneFrame + 20_000)
        for i in 0...3 {
            _ = try t.detectForVideo(bytes: clip.frame(i), desc: clip.desc, timestampMs: Int64(33 * i))
        }
        let s = try t.stopRecording()
        XCTAssertTrue(s.truncated)
        XCTAssertEqual(s.frames, 1)
        XCTAssertLessThanOrEqual(try fileSize(file), oneFrame + 20_000)
    }
}
