// The live-stream mode (the wrapper's LiveTracker and the generated LiveFaceTracker) and the intrinsics
// convention against the real library (the port of bindings/tests/kotlin/LiveStreamTest.kt): events in
// timestamp order, frames dropped while the worker is busy and each counted once, shutdown while
// busy, bad frames refused at once, taps on the worker.
import Foundation
import XCTest
@testable import Monotrack

/// The sample face as upright 8-bit luma, cropped to a landscape 512×400.
private func upright() throws -> (width: Int, height: Int, pixels: [UInt8]) {
    let img = try sample()
    let (w, h) = (512, 400)
    var out = [UInt8](repeating: 0, count: w * h)
    for y in 0..<h { for x in 0..<w { out[y * w + x] = img.luma(x, y + 40) } }
    return (w, h, out)
}

/// The sensor buffer that turning by `rot` then mirroring makes into the upright picture.
private func sensorBuffer(_ u: (width: Int, height: Int, pixels: [UInt8]), rot: Int, mirrored: Bool)
    -> (width: Int, height: Int, pixels: [UInt8])
{
    let (uw, uh) = (u.width, u.height)
    let (bw, bh) = rot % 180 == 90 ? (uh, uw) : (uw, uh)
    var b = [UInt8](repeating: 0, count: bw * bh)
    for oy in 0..<uh {
        for ox in 0..<uw {
            let cx = mirrored ? uw - 1 - ox : ox
            let (x, y): (Int, Int)
            switch rot {
            case 0: (x, y) = (cx, oy)
            case 90: (x, y) = (oy, bh - 1 - cx)
            case 180: (x, y) = (bw - 1 - cx, bh - 1 - oy)
            default: (x, y) = (bw - 1 - oy, cx)
            }
            b[y * bw + x] = u.pixels[oy * uw + ox]
        }
    }
    return (bw, bh, b)
}

/// Intrinsics of a `w`×`h` image turned clockwise by `rot` (as the SDK documents the turn).
private func turned(_ k: CameraIntrinsics, w: Int, h: Int, rot: Int) -> CameraIntrinsics {
    switch rot {
    case 0: return k
    case 90: return CameraIntrinsics(fx: k.fy, fy: k.fx, cx: Double(h) - k.cy, cy: k.cx)
    case 180: return CameraIntrinsics(fx: k.fx, fy: k.fy, cx: Double(w) - k.cx, cy: Double(h) - k.cy)
    default: return CameraIntrinsics(fx: k.fy, fy: k.fx, cx: k.cy, cy: Double(w) - k.cx)
    }
}

/// One delivery of the generated listener.
private struct Delivery {
    let timestampNs: Int64
    let framesDropped: UInt64
    let faces: Int?
    let error: MonotrackError?
}

/// A listener of the generated LiveFaceTracker that records each delivery, optionally sleeping on the
/// worker's thread (a slow consumer), and signals when the delivery of `until` arrives.
private final class Recorder: LiveStreamListener, @unchecked Sendable {
    private let lock = NSLock()
    private var list: [Delivery] = []
    private let sleepMs: UInt32
    private let until: Int64
    let arrived = DispatchSemaphore(value: 0)

    init(sleepMs: UInt32 = 0, until: Int64 = -1) {
        self.sleepMs = sleepMs
        self.until = until
    }

    var deliveries: [Delivery] { lock.lock(); defer { lock.unlock() }; return list }

    private func record(_ d: Delivery) {
        lock.lock()
        list.append(d)
        lock.unlock()
        if sleepMs > 0 { usleep(sleepMs * 1000) }
        if d.timestampNs == until { arrived.signal() }
    }

    func onResult(result: LiveStreamResult) {
        record(Delivery(timestampNs: result.timestampNs, framesDropped: result.framesDropped,
                        faces: result.result.faces.count, error: nil))
    }

    func onError(timestampNs: Int64, framesDropped: UInt64, error: MonotrackError) {
        record(Delivery(timestampNs: timestampNs, framesDropped: framesDropped, faces: nil, error: error))
    }
}

extension LiveEvent {
    var timestampNs: Int64 {
        switch self {
        case .faces(let r): return r.timestampNs
        case .failed(let t, _, _): return t
        }
    }

    var framesDropped: UInt64 {
        switch self {
        case .faces(let r): return r.framesDropped
        case .failed(_, let d, _): return d
        }
    }
}

/// Shuts `tracker` down (ending its events) after `seconds` unless cancelled: a stuck test fails.
private func watchdog(_ tracker: LiveTracker, seconds: Double = 60) -> Task<Void, Never> {
    Task {
        try? await Task.sleep(nanoseconds: UInt64(seconds * 1e9))
        if !Task.isCancelled { tracker.shutdown() }
    }
}

final class LiveStreamTests: XCTestCase {
    private func facePose(_ b: (width: Int, height: Int, pixels: [UInt8]), rot: Int, mirrored: Bool,
                          _ k: CameraIntrinsics) throws -> HeadPose {
        let t = try Monotrack.FaceTracker(config: with(defaultTrackerConfig()) { $0.runningMode = .image; $0.camera = k })
        let f = grayFrame(b.pixels, width: b.width, height: b.height, rot: UInt32(rot), mirrored: mirrored)
        let r = try t.processFrame(bytes: f.bytes, desc: f.desc, timestampNs: 0)
        XCTAssertEqual(r.faces.count, 1, "rotation \(rot) mirrored \(mirrored)")
        return try XCTUnwrap(r.faces.first).pose
    }

    func testSensorIntrinsicsGiveTheSamePoseInEveryOrientation() throws {
        let u = try upright()
        let ku = CameraIntrinsics(fx: 520, fy: 545, cx: 0.42 * Double(u.width), cy: 0.58 * Double(u.height))
        let ref = try facePose(u, rot: 0, mirrored: false, ku)
        for rot in [0, 90, 180, 270] {
            for mirrored in [false, true] {
                let b = sensorBuffer(u, rot: rot, mirrored: mirrored)
                var m = ku
                if mirrored { m.cx = Double(u.width) - ku.cx }
                let pose = try facePose(b, rot: rot, mirrored: mirrored, turned(m, w: u.width, h: u.height, rot: (360 - rot) % 360))
                let t = [pose.translationMm.x, pose.translationMm.y, pose.translationMm.z]
                let tr = [ref.translationMm.x, ref.translationMm.y, ref.translationMm.z]
                for i in 0..<3 { XCTAssertEqual(t[i], tr[i], accuracy: 1e-3, "rot \(rot) mirrored \(mirrored): t \(t) vs \(tr)") }
                for i in 0..<9 { XCTAssertEqual(pose.rotation[i], ref.rotation[i], accuracy: 1e-6, "rot \(rot) mirrored \(mirrored): R") }
            }
        }
        // The wrapper's field-of-view intrinsics: f from the horizontal angle, centred.
        let k = try XCTUnwrap(CameraIntrinsics(fieldOfViewDegrees: 90, width: 640, height: 480))
        XCTAssertEqual(k.fx, 320, accuracy: 1e-9)
        XCTAssertEqual(k.cy, 240, accuracy: 1e-9)
        XCTAssertNil(CameraIntrinsics(fieldOfViewDegrees: 180, width: 640, height: 480))
        XCTAssertNil(CameraIntrinsics(fieldOfViewDegrees: 60, width: 0, height: 480))
    }

    /// The generated API with a consumer slower than the camera (as the Kotlin listener test).
    func testFramesAreDroppedWhileBusyAndEventsStayInOrder() throws {
        let u = try upright()
        let submitted: Int64 = 40
        let recorder = Recorder(sleepMs: 15, until: submitted * 1_000_000)
        let t = try LiveFaceTracker(config: defaultTrackerConfig(), listener: recorder)
        var replaced: UInt64 = 0
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        for i in 1...submitted {
            if try t.processAsync(bytes: f.bytes, desc: f.desc, timestampNs: i * 1_000_000) { replaced += 1 }
            usleep(2000)
        }
        XCTAssertEqual(recorder.arrived.wait(timeout: .now() + 60), .success, "the newest frame is always delivered")
        t.shutdown()
        let list = recorder.deliveries
        let ts = list.map(\.timestampNs)
        XCTAssertEqual(ts, ts.sorted(), "in timestamp order")
        XCTAssertEqual(Set(ts).count, ts.count)
        XCTAssertTrue(list.allSatisfy { $0.faces == 1 }, "every event found the face")
        let dropped = list.map(\.framesDropped).reduce(0, +)
        XCTAssertEqual(dropped, replaced, "each replaced frame counted once")
        XCTAssertEqual(UInt64(list.count) + dropped, UInt64(submitted), "every frame delivered or counted dropped")
        XCTAssertGreaterThan(dropped, 0, "a 15 ms consumer fed every 2 ms drops frames")
    }

    /// The wrapper's stream: the same accounting, the events in timestamp order.
    func testTheWrapperStreamKeepsOrderAndCountsEveryFrame() async throws {
        let u = try upright()
        let tracker = try LiveTracker()
        let dog = watchdog(tracker)
        let submitted: Int64 = 30
        let collector = Task { () -> [LiveEvent] in
            var got: [LiveEvent] = []
            for await e in tracker.events {
                got.append(e)
                if e.timestampNs == submitted * 1_000_000 { break }
            }
            return got
        }
        var replaced: UInt64 = 0
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        for i in 1...submitted {
            if try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: i * 1_000_000) { replaced += 1 }
            usleep(2000)
        }
        let events = await collector.value
        dog.cancel()
        tracker.shutdown()
        XCTAssertEqual(events.last?.timestampNs, submitted * 1_000_000, "the newest frame is always delivered")
        let ts = events.map(\.timestampNs)
        XCTAssertEqual(ts, ts.sorted(), "in timestamp order")
        XCTAssertEqual(Set(ts).count, ts.count)
        for e in events {
            guard case .faces(let r) = e else { XCTFail("\(e)"); continue }
            XCTAssertEqual(r.result.faces.count, 1, "every event found the face")
        }
        let dropped = events.map(\.framesDropped).reduce(0, +)
        XCTAssertEqual(dropped, replaced, "each replaced frame counted once")
        XCTAssertEqual(UInt64(events.count) + dropped, UInt64(submitted), "every frame delivered or counted dropped")
    }

    func testShutdownWhileBusyStopsDeliveriesAndLaterFramesAreRefused() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        // The generated API: nothing is delivered after shutdown returns.
        let recorder = Recorder()
        let raw = try LiveFaceTracker(config: defaultTrackerConfig(), listener: recorder)
        _ = try raw.processAsync(bytes: f.bytes, desc: f.desc, timestampNs: 1)
        _ = try raw.processAsync(bytes: f.bytes, desc: f.desc, timestampNs: 2)
        raw.shutdown()
        let atShutdown = recorder.deliveries.count
        XCTAssertLessThanOrEqual(atShutdown, 2)
        usleep(300_000)
        XCTAssertEqual(recorder.deliveries.count, atShutdown, "no delivery after shutdown returns")
        raw.shutdown()
        assertInvalidFrame(try raw.processAsync(bytes: f.bytes, desc: f.desc, timestampNs: 3), "after shutdown")

        // The wrapper: shutdown ends the stream (a frame in flight may still arrive) and is idempotent.
        let tracker = try LiveTracker()
        let dog = watchdog(tracker, seconds: 30)
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 1)
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 2)
        tracker.shutdown()
        var seen = 0
        for await _ in tracker.events { seen += 1 }
        dog.cancel()
        XCTAssertLessThanOrEqual(seen, 2)
        tracker.shutdown()
        assertInvalidFrame(try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 3), "after shutdown")
    }

    func testBadFramesThrowAtOnceAndTheStreamGoesOn() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        let tracker = try LiveTracker()
        let dog = watchdog(tracker)
        assertInvalidFrame(try tracker.process(bytes: Data(count: 10), desc: f.desc, timestampNs: 5))
        var it = tracker.events.makeAsyncIterator()
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 10)
        let first = await it.next()
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 20)
        let second = await it.next()
        dog.cancel()
        tracker.shutdown()
        XCTAssertEqual(first?.timestampNs, 10, "the bad frame left no event")
        XCTAssertEqual(second?.timestampNs, 20)
        guard case .faces(let r) = second else { return XCTFail("\(String(describing: second))") }
        XCTAssertEqual(r.result.faces.count, 1)
    }

    func testEventsFlowToCollectors() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        let tracker = try LiveTracker()
        let dog = watchdog(tracker)
        let first = Task { () -> LiveEvent? in
            for await e in tracker.events { return e }
            return nil
        }
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 7)
        let e = await first.value
        dog.cancel()
        tracker.shutdown()
        XCTAssertEqual(e?.timestampNs, 7)
        guard case .faces(let r) = e else { return XCTFail("\(String(describing: e))") }
        XCTAssertEqual(r.result.faces.count, 1)
        XCTAssertEqual(r.framesDropped, 0)
    }

    func testTapsCalibrateTheLiveTrackerAndUnusableOnesArriveAsFailures() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        let tracker = try LiveTracker()
        let dog = watchdog(tracker)
        var it = tracker.events.makeAsyncIterator()
        try tracker.setGazeTargets([screenTarget(id: "phone", widthMm: 70, heightMm: 150, cameraRightMm: 35, cameraDownMm: -8)])
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 10_000_000)
        let e1 = await it.next()
        guard case .faces = e1 else { dog.cancel(); return XCTFail("\(String(describing: e1))") }
        assertInvalidConfig(try tracker.addCalibrationPoint(targetId: "tv", point: PlanePoint(uMm: 35, vMm: 50), timestampNs: 10_000_000))
        try tracker.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 35, vMm: 50), timestampNs: 12_000_000)
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 43_000_000)
        let after = await it.next()
        guard case .faces(let r) = after else { dog.cancel(); return XCTFail("\(String(describing: after))") }
        let hit = try XCTUnwrap(r.result.faces.first?.pointOfGaze?.target)
        XCTAssertTrue(hit.hit && abs(hit.point.uMm - 35) < 10 && abs(hit.point.vMm - 50) < 10, "\(hit)")
        // No face near this tap's time: the stream says so, then brings the frame's faces.
        try tracker.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 35, vMm: 50), timestampNs: 900_000_000)
        try tracker.process(bytes: f.bytes, desc: f.desc, timestampNs: 950_000_000)
        let failed = await it.next()
        let last = await it.next()
        dog.cancel()
        tracker.shutdown()
        guard case .failed(let ts, _, let error) = failed else { return XCTFail("\(String(describing: failed))") }
        XCTAssertEqual(ts, 900_000_000)
        guard case .InvalidFrame = error else { return XCTFail("\(error)") }
        guard case .faces = last else { return XCTFail("\(String(describing: last))") }
        tracker.resetGazeCalibration()
    }
}
