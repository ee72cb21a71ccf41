// The live-stream running mode (the generated FaceTracker with a listener of its own, and the wrapper's
// LiveEvents) and the intrinsics convention against the real library (the port of
// bindings/tests/kotlin/LiveStreamTest.kt): events in timestamp order, frames dropped while the
// worker is busy and each counted once, shutdown while busy, bad frames and timestamps refused at
// once, reset, taps on the worker.
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
    let timestampMs: Int64
    let framesDropped: UInt64
    let faces: Int?
    let error: MonotrackError?
}

/// A listener of the generated API that records each delivery, optionally sleeping on the worker's
/// thread (a slow consumer), and signals when the delivery of `until` arrives.
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
        if d.timestampMs == until { arrived.signal() }
    }

    func onResult(result: LiveStreamResult) {
        record(Delivery(timestampMs: result.timestampMs, framesDropped: result.framesDropped,
                        faces: result.result.faces.count, error: nil))
    }

    func onError(timestampMs: Int64, framesDropped: UInt64, error: MonotrackError) {
        record(Delivery(timestampMs: timestampMs, framesDropped: framesDropped, faces: nil, error: error))
    }
}

/// A live-stream tracker delivering to `events`, with the default options otherwise.
private func liveTracker(_ events: LiveStreamListener) throws -> FaceTracker {
    try FaceTracker(options: options(.liveStream), listener: events)
}

/// Shuts `tracker` down and ends `events` after `seconds` unless cancelled: a stuck test fails
/// instead of hanging.
private func watchdog(_ tracker: FaceTracker, _ events: LiveEvents, seconds: Double = 60) -> Task<Void, Never> {
    Task {
        try? await Task.sleep(nanoseconds: UInt64(seconds * 1e9))
        if !Task.isCancelled {
            tracker.shutdown()
            events.finish()
        }
    }
}

final class LiveStreamTests: XCTestCase {
    private func facePose(_ b: (width: Int, height: Int, pixels: [UInt8]), rot: Int, mirrored: Bool,
                          _ k: CameraIntrinsics) throws -> HeadPose {
        let t = try FaceTracker(options: with(FaceTrackerOptions()) { $0.camera = k })
        let f = grayFrame(b.pixels, width: b.width, height: b.height, rot: UInt32(rot), mirrored: mirrored)
        let r = try t.detect(bytes: f.bytes, desc: f.desc)
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
        // The result names the upright image's intrinsics: the sensor's turned with the frame.
        let b = sensorBuffer(u, rot: 90, mirrored: false)
        let k90 = turned(ku, w: u.width, h: u.height, rot: 270)
        let f = grayFrame(b.pixels, width: b.width, height: b.height, rot: 90)
        let r = try FaceTracker(options: with(FaceTrackerOptions()) { $0.camera = k90 }).detect(bytes: f.bytes, desc: f.desc)
        XCTAssertEqual(r.camera.fx, ku.fx, accuracy: 1e-9)
        XCTAssertEqual(r.camera.fy, ku.fy, accuracy: 1e-9)
        XCTAssertEqual(r.camera.cx, ku.cx, accuracy: 1e-9)
        XCTAssertEqual(r.camera.cy, ku.cy, accuracy: 1e-9)
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
        let recorder = Recorder(sleepMs: 15, until: submitted)
        let t = try liveTracker(recorder)
        var replaced: UInt64 = 0
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        for i in 1...submitted {
            if try t.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: i) { replaced += 1 }
            usleep(2000)
        }
        XCTAssertEqual(recorder.arrived.wait(timeout: .now() + 60), .success, "the newest frame is always delivered")
        t.shutdown()
        let list = recorder.deliveries
        let ts = list.map(\.timestampMs)
        XCTAssertEqual(ts, ts.sorted(), "in timestamp order")
        XCTAssertEqual(Set(ts).count, ts.count)
        XCTAssertTrue(list.allSatisfy { $0.faces == 1 }, "every event found the face")
        let dropped = list.map(\.framesDropped).reduce(0, +)
        XCTAssertEqual(dropped, replaced, "each replaced frame counted once")
        XCTAssertEqual(UInt64(list.count) + dropped, UInt64(submitted), "every frame delivered or counted dropped")
        XCTAssertGreaterThan(dropped, 0, "a 15 ms consumer fed every 2 ms drops frames")
    }

    /// The wrapper's stream: the same accounting, the events in timestamp order.
    func testLiveEventsKeepOrderAndCountEveryFrame() async throws {
        let u = try upright()
        let events = LiveEvents()
        let tracker = try FaceTracker(options: FaceTrackerOptions(runningMode: .liveStream), listener: events)
        let dog = watchdog(tracker, events)
        let submitted: Int64 = 30
        let collector = Task { () -> [LiveEvent] in
            var got: [LiveEvent] = []
            for await e in events.events {
                got.append(e)
                if e.timestampMs == submitted { break }
            }
            return got
        }
        var replaced: UInt64 = 0
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        for i in 1...submitted {
            if try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: i) { replaced += 1 }
            usleep(2000)
        }
        let got = await collector.value
        dog.cancel()
        tracker.shutdown()
        events.finish()
        XCTAssertEqual(got.last?.timestampMs, submitted, "the newest frame is always delivered")
        let ts = got.map(\.timestampMs)
        XCTAssertEqual(ts, ts.sorted(), "in timestamp order")
        XCTAssertEqual(Set(ts).count, ts.count)
        for e in got {
            guard case .faces(let r) = e else { XCTFail("\(e)"); continue }
            XCTAssertEqual(r.result.faces.count, 1, "every event found the face")
        }
        let dropped = got.map(\.framesDropped).reduce(0, +)
        XCTAssertEqual(dropped, replaced, "each replaced frame counted once")
        XCTAssertEqual(UInt64(got.count) + dropped, UInt64(submitted), "every frame delivered or counted dropped")
    }

    func testShutdownWhileBusyStopsDeliveriesAndLaterCallsAreRefused() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        // The generated API: nothing is delivered after shutdown returns.
        let recorder = Recorder()
        let raw = try liveTracker(recorder)
        _ = try raw.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 1)
        _ = try raw.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 2)
        raw.shutdown()
        let atShutdown = recorder.deliveries.count
        XCTAssertLessThanOrEqual(atShutdown, 2)
        usleep(300_000)
        XCTAssertEqual(recorder.deliveries.count, atShutdown, "no delivery after shutdown returns")
        raw.shutdown()
        assertInvalidState(try raw.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 3), "after shutdown")
        assertInvalidState(try raw.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 1, vMm: 1), timestampMs: 3),
                           "a tap after shutdown")

        // The wrapper: finishing after shutdown ends the stream with whatever was in flight, and
        // both are idempotent.
        let events = LiveEvents()
        let tracker = try liveTracker(events)
        let dog = watchdog(tracker, events, seconds: 30)
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 1)
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 2)
        tracker.shutdown()
        events.finish()
        var seen = 0
        for await _ in events.events { seen += 1 }
        dog.cancel()
        XCTAssertLessThanOrEqual(seen, 2)
        tracker.shutdown()
        events.finish()
        assertInvalidState(try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 3), "after shutdown")
    }

    /// Bad frames, repeated timestamps and another mode's call are refused at once and leave no
    /// event; `reset()` lets a restarted camera's earlier clock in.
    func testBadCallsThrowAtOnceAndResetRestartsTheClock() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        let events = LiveEvents()
        let tracker = try liveTracker(events)
        let dog = watchdog(tracker, events)
        assertInvalidFrame(try tracker.detectAsync(bytes: Data(count: 10), desc: f.desc, timestampMs: 5))
        assertInvalidState(try tracker.detectForVideo(bytes: f.bytes, desc: f.desc, timestampMs: 5), "a video call")
        assertInvalidState(try tracker.detect(bytes: f.bytes, desc: f.desc), "a still call")
        var it = events.events.makeAsyncIterator()
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 10)
        assertInvalidTimestamp(try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 10), "a repeated time")
        let first = await it.next()
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 20)
        let second = await it.next()
        tracker.reset()
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 3)
        let third = await it.next()
        dog.cancel()
        tracker.shutdown()
        events.finish()
        XCTAssertEqual(first?.timestampMs, 10, "the refused calls left no event")
        XCTAssertEqual(second?.timestampMs, 20)
        XCTAssertEqual(third?.timestampMs, 3, "after reset an earlier time is taken")
        guard case .faces(let r) = second else { return XCTFail("\(String(describing: second))") }
        XCTAssertEqual(r.result.faces.count, 1)
        guard case .faces(let again) = third else { return XCTFail("\(String(describing: third))") }
        XCTAssertEqual(again.result.faces.first?.state, .detected, "reset ended the track")
    }

    func testEventsFlowToCollectors() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        let events = LiveEvents()
        let tracker = try liveTracker(events)
        let dog = watchdog(tracker, events)
        let first = Task { () -> LiveEvent? in
            for await e in events.events { return e }
            return nil
        }
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 7)
        let e = await first.value
        dog.cancel()
        tracker.shutdown()
        events.finish()
        XCTAssertEqual(e?.timestampMs, 7)
        guard case .faces(let r) = e else { return XCTFail("\(String(describing: e))") }
        XCTAssertEqual(r.result.faces.count, 1)
        XCTAssertEqual(r.framesDropped, 0)
        XCTAssertEqual(r.result.frameWidth, UInt32(u.width))
    }

    func testTapsCalibrateTheLiveTrackerAndUnusableOnesArriveAsFailures() async throws {
        let u = try upright()
        let f = grayFrame(u.pixels, width: u.width, height: u.height)
        let events = LiveEvents()
        let tracker = try liveTracker(events)
        let dog = watchdog(tracker, events)
        var it = events.events.makeAsyncIterator()
        try tracker.setGazeTargets(targets: [screenTarget(id: "phone", widthMm: 70, heightMm: 150, cameraRightMm: 35, cameraDownMm: -8)])
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 10)
        let e1 = await it.next()
        guard case .faces = e1 else { dog.cancel(); return XCTFail("\(String(describing: e1))") }
        assertInvalidConfig(try tracker.addCalibrationPoint(targetId: "tv", point: PlanePoint(uMm: 35, vMm: 50), timestampMs: 10))
        XCTAssertNil(try tracker.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 35, vMm: 50), timestampMs: 12),
                     "the worker learns the tap later: no count yet")
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 43)
        let after = await it.next()
        guard case .faces(let r) = after else { dog.cancel(); return XCTFail("\(String(describing: after))") }
        let hit = try XCTUnwrap(r.result.faces.first?.pointOfGaze?.target)
        XCTAssertTrue(hit.hit && abs(hit.point.uMm - 35) < 10 && abs(hit.point.vMm - 50) < 10, "\(hit)")
        // No face near this tap's time: the stream says so, then brings the frame's faces.
        _ = try tracker.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 35, vMm: 50), timestampMs: 900)
        _ = try tracker.detectAsync(bytes: f.bytes, desc: f.desc, timestampMs: 950)
        let failed = await it.next()
        let last = await it.next()
        tracker.resetGazeCalibration()
        dog.cancel()
        tracker.shutdown()
        events.finish()
        guard case .failed(let ts, _, let error) = failed else { return XCTFail("\(String(describing: failed))") }
        XCTAssertEqual(ts, 900)
        guard case .InvalidFrame = error else { return XCTFail("\(error)") }
        guard case .faces = last else { return XCTFail("\(String(describing: last))") }
    }
}
