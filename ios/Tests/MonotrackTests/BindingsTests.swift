// The generated Swift against the real library (the Swift port of bindings/tests/kotlin/BindingsTest.kt):
// frames of the sample image in every pixel format with padded strides through every rotation and
// mirroring and the SDK's frame rules on them, the options' defaults, the running modes, tracking
// across frames and reset, timestamps, the results' eyes and transform, the landmark fit, the body
// tracker, the benchmark, typed errors.
import Foundation
import XCTest
@testable import Monotrack

/// The examples' landmarks68 of line `line` (examples/fit_example.jsonl, the first face).
private func exampleLandmarks(_ line: Int) throws -> [Point2] {
    let faces = try jsonLines("examples/fit_example.jsonl")[line]["faces"] as? [[String: Any]]
    return points2(faces?.first?["landmarks68"])
}

/// A JSON array of `[x, y]` pairs.
private func points2(_ v: Any?) -> [Point2] {
    var out: [Point2] = []
    for p in v as? [Any] ?? [] {
        let xy: [Double] = doubles(p)
        out.append(Point2(x: Float(xy[0]), y: Float(xy[1])))
    }
    return out
}

/// CONTRACT joint names in `BodyJoint` order.
private let jointNames = [
    "pelvis", "thorax", "lshoulder", "lelbow", "lwrist", "rshoulder", "relbow", "rwrist",
    "lhip", "lknee", "lankle", "rhip", "rknee", "rankle", "head",
]
private let joints: [BodyJoint] = [
    .pelvis, .thorax, .lShoulder, .lElbow, .lWrist, .rShoulder, .rElbow, .rWrist,
    .lHip, .lKnee, .lAnkle, .rHip, .rKnee, .rAnkle, .head,
]

final class BindingsTests: XCTestCase {
    func testVersionIsTheCrateVersion() {
        let parts = sdkVersion().split(separator: ".", omittingEmptySubsequences: false)
        XCTAssertEqual(parts.count, 3, sdkVersion())
        XCTAssertTrue(parts.allSatisfy { !$0.isEmpty && $0.allSatisfy(\.isNumber) }, sdkVersion())
    }

    func testEveryPixelFormatWithPaddedStridesInEveryRotation() throws {
        let img = try sample()
        let formats: [PixelFormat] = [.rgba8, .bgra8, .rgb8, .gray8, .nv21, .nv12, .i420]
        for format in formats {
            for rot in [0, 90, 180, 270] {
                for mirrored in [false, true] {
                    let f = sampleFrame(img, format, rot: UInt32(rot), mirrored: mirrored)
                    let out = try lumaImage(bytes: f.bytes, desc: f.desc)
                    let want = reference(img, rot: rot, mirrored: mirrored)
                    XCTAssertEqual(out.width, UInt32(want.width), "\(format) rot \(rot)")
                    XCTAssertEqual(out.height, UInt32(want.height), "\(format) rot \(rot)")
                    XCTAssertEqual([UInt8](out.pixels), want.pixels, "\(format) rot \(rot) mirrored \(mirrored)")
                }
            }
        }
    }

    /// The SDK's frame rules agree with the test's own layouts: the upright size is the reference
    /// conversion's, and `frameByteCount` is exactly what `lumaImage` accepts (one byte less is
    /// refused).
    func testFrameByteCountAndUprightSizeAgreeWithTheFrames() throws {
        let img = try sample()
        let formats: [PixelFormat] = [.rgba8, .bgra8, .rgb8, .gray8, .nv21, .nv12, .i420]
        let halfWidth = (img.width + 1) / 2
        for format in formats {
            for rot in [0, 90, 180, 270] {
                let f = sampleFrame(img, format, rot: UInt32(rot), mirrored: rot == 90)
                let size = try uprightSize(desc: f.desc)
                let want = reference(img, rot: rot, mirrored: false)
                XCTAssertEqual(size, FrameSize(width: UInt32(want.width), height: UInt32(want.height)), "\(format) rot \(rot)")
                // Packed frames are built with a short last row; the YUV ones end with a full
                // chroma row, of which the SDK needs only the samples.
                let unused: Int
                switch format {
                case .nv21, .nv12: unused = Int(f.desc.uvRowStride) - 2 * halfWidth
                case .i420: unused = Int(f.desc.uvRowStride) - halfWidth
                default: unused = 0
                }
                let count = try frameByteCount(desc: f.desc)
                XCTAssertEqual(count, UInt64(f.bytes.count - unused), "\(format) rot \(rot)")
                if rot == 0 {
                    XCTAssertNoThrow(try lumaImage(bytes: f.bytes.prefix(Int(count)), desc: f.desc), "\(format)")
                    assertInvalidFrame(try lumaImage(bytes: f.bytes.prefix(Int(count) - 1), desc: f.desc), "\(format)")
                }
            }
        }
        let (_, d) = sampleFrame(img, .rgba8)
        assertInvalidFrame(try frameByteCount(desc: with(d) { $0.rowStride = UInt32(img.width * 4 - 1) }), "stride")
        assertInvalidFrame(try uprightSize(desc: with(d) { $0.rotationDegrees = 45 }), "rotation")
    }

    func testBadFramesRaiseInvalidFrame() throws {
        let img = try sample()
        let (buf, d) = sampleFrame(img, .rgba8)
        let msg = assertInvalidFrame(try lumaImage(bytes: buf.dropLast(), desc: d), "short buffer")
        XCTAssertTrue(msg?.contains("needs") == true, msg ?? "")
        assertInvalidFrame(try lumaImage(bytes: buf, desc: with(d) { $0.rowStride = UInt32(img.width * 4 - 1) }), "stride")
        assertInvalidFrame(try lumaImage(bytes: buf, desc: with(d) { $0.rotationDegrees = 45 }), "rotation")
        let (nv, nd) = sampleFrame(img, .nv21)
        assertInvalidFrame(try lumaImage(bytes: nv, desc: with(nd) { $0.uvPixelStride = 1 }), "interleaved chroma")
        let (i420, id) = sampleFrame(img, .i420)
        // The V plane's last row may end right after its samples, not one byte before.
        let needed = i420.count - (Int(id.uvRowStride) - (img.width + 1) / 2)
        XCTAssertNoThrow(try lumaImage(bytes: i420.prefix(needed), desc: id))
        assertInvalidFrame(try lumaImage(bytes: i420.prefix(needed - 1), desc: id), "short V plane")
        let zero = FrameDesc(width: 0, height: 10, format: .gray8, rowStride: 0, uvRowStride: 0, uvPixelStride: 0,
                             rotationDegrees: 0, mirrored: false)
        assertInvalidFrame(try lumaImage(bytes: buf, desc: zero), "zero size")
        // The error is a LocalizedError whose description carries the message.
        do {
            _ = try lumaImage(bytes: Data(count: 10), desc: d)
            XCTFail("no error")
        } catch let e as MonotrackError {
            guard case .InvalidFrame(let m) = e else { return XCTFail("\(e)") }
            XCTAssertFalse(m.isEmpty)
            XCTAssertEqual(e, .InvalidFrame(msg: m))
        }
    }

    func testFitRecoversTheExamplePoses() throws {
        let frontal = try fitLandmarks(landmarks: exampleLandmarks(0), width: 640, height: 480, camera: nil, method: .msbp)
        XCTAssertEqual(frontal.pose.yawDeg, 0, accuracy: 1.5)
        XCTAssertEqual(frontal.pose.translationMm.z, 600, accuracy: 18)
        // Named fields, no strings per frame: a neutral example face neither smiles nor opens its mouth.
        XCTAssertLessThan(abs(frontal.actionUnits.smile), 0.5)
        XCTAssertTrue(frontal.shapeUnits.faceLength.isFinite)
        let turned = try fitLandmarks(landmarks: exampleLandmarks(1), width: 640, height: 480, camera: nil, method: .ffbp)
        XCTAssertEqual(turned.pose.yawDeg, -35, accuracy: 5)
        XCTAssertLessThan(turned.fitRmsPx, 5)
    }

    func testBadFitInputRaisesInvalidConfig() throws {
        let l = try exampleLandmarks(0)
        assertInvalidConfig(try fitLandmarks(landmarks: Array(l.prefix(10)), width: 640, height: 480, camera: nil, method: .msbp))
        let nanCamera = CameraIntrinsics(fx: .nan, fy: 500, cx: 320, cy: 240)
        assertInvalidConfig(try fitLandmarks(landmarks: l, width: 640, height: 480, camera: nanCamera, method: .msbp))
    }

    /// The uniffi literals behind `FaceTrackerOptions()` are Rust's defaults, field by field (a
    /// default that moves in Rust fails here until the literal follows).
    func testOptionsLiteralDefaultsAreRusts() {
        let swift = FaceTrackerOptions()
        let rust = defaultFaceTrackerOptions()
        XCTAssertEqual(swift.runningMode, rust.runningMode)
        XCTAssertNil(swift.runningMode, "nil is MediaPipe's image mode")
        XCTAssertEqual(swift.numFaces, rust.numFaces)
        XCTAssertEqual(swift.minFaceDetectionConfidence, rust.minFaceDetectionConfidence)
        XCTAssertEqual(swift.minFacePresenceConfidence, rust.minFacePresenceConfidence)
        XCTAssertEqual(swift.minTrackingConfidence, rust.minTrackingConfidence)
        XCTAssertEqual(swift.outputActionUnits, rust.outputActionUnits)
        XCTAssertEqual(swift.outputFacialTransformationMatrixes, rust.outputFacialTransformationMatrixes)
        XCTAssertEqual(swift.outputGestures, rust.outputGestures)
        XCTAssertEqual(swift.outputGaze, rust.outputGaze)
        XCTAssertEqual(swift.camera, rust.camera)
        let (t, r) = (swift.tuning, rust.tuning)
        XCTAssertEqual(t.minFaceSizePx, r.minFaceSizePx)
        XCTAssertEqual(t.minMatchScore, r.minMatchScore)
        XCTAssertEqual(t.searchMargin, r.searchMargin)
        XCTAssertEqual(t.flowFilter, r.flowFilter)
        XCTAssertEqual(t.gazeFilter, r.gazeFilter)
        XCTAssertEqual(t.shapeFrames, r.shapeFrames)
        XCTAssertEqual(t.mirrorAverage, r.mirrorAverage)
        XCTAssertEqual(t.ultraLight, r.ultraLight)
        XCTAssertEqual(t, TrackerTuning())
        XCTAssertNil(swift.models, "the built-in models")
        XCTAssertNil(rust.models)
        // The ultra-light options differ from the defaults only where they say so.
        let light = ultraLightFaceTrackerOptions(runningMode: .video)
        XCTAssertEqual(light.runningMode, .video)
        XCTAssertTrue(light.tuning.ultraLight)
        XCTAssertEqual(light.numFaces, rust.numFaces)
        XCTAssertEqual(light.minFaceDetectionConfidence, rust.minFaceDetectionConfidence)
    }

    func testTrackerFindsTracksAndRejectsBadInput() throws {
        let img = try sample()
        let t = try FaceTracker(options: options(.video))
        XCTAssertEqual(t.options().runningMode, .video)
        let (buf, d) = sampleFrame(img, .rgba8)
        let first = try t.detectForVideo(bytes: buf, desc: d, timestampMs: 1)
        XCTAssertEqual(first.faces.count, 1, "one face in the astronaut portrait")
        XCTAssertEqual(first.camera, try defaultCamera(width: UInt32(img.width), height: UInt32(img.height)),
                       "the result names the intrinsics it was fitted with")
        let f = try XCTUnwrap(first.faces.first)
        XCTAssertEqual(f.state, .detected)
        XCTAssertEqual(f.landmarks.count, 68)
        XCTAssertNil(f.landmarkConfidence, "M3 measures every point")
        // The nose tip lies inside the astronaut's face box (x 176–273, y 88–181 px: the union of the
        // boxes the first and the current detector model find).
        let nose = f.landmarks[30]
        XCTAssertTrue((176...273).contains(nose.x) && (88...181).contains(nose.y), "nose at \(nose)")
        XCTAssertLessThan(abs(f.pose.yawDeg), 30, "frontal")
        XCTAssertTrue((200...2000).contains(f.pose.translationMm.z))
        XCTAssertTrue(f.shapeUnits.eyesWidth.isFinite)
        XCTAssertTrue(try XCTUnwrap(f.actionUnits).openMouth.isFinite)
        // BGRA (the iPhone's packed format) and gray (NV12's luma plane, as a CVPixelBuffer reaches
        // the SDK) keep the same track.
        let (bgra, bd) = sampleFrame(img, .bgra8)
        let (gray, gd) = sampleFrame(img, .gray8)
        for (k, frame) in [(bgra, bd), (gray, gd), (buf, d)].enumerated() {
            let r = try t.detectForVideo(bytes: frame.0, desc: frame.1, timestampMs: Int64(2 + k))
            XCTAssertEqual(r.faces.first?.state, .tracked, "frame \(k)")
            XCTAssertEqual(r.faces.first?.id, f.id, "frame \(k)")
        }
        assertInvalidFrame(try t.detectForVideo(bytes: Data(count: 10), desc: d, timestampMs: 10), "short buffer")
        t.reset()
        XCTAssertEqual(try t.detectForVideo(bytes: buf, desc: d, timestampMs: 1).faces.first?.state, .detected,
                       "reset ends the tracks")
        // Stills: every call detects afresh, with no timestamps.
        let stills = try FaceTracker(options: FaceTrackerOptions())
        let (nv, nd) = nv21SensorFrame(img)
        for _ in 0..<2 {
            let still = try stills.detect(bytes: nv, desc: nd)
            XCTAssertEqual(still.faces.count, 1, "the face in the rotated NV21 frame")
            XCTAssertEqual(still.faces.first?.state, .detected)
            XCTAssertEqual(still.frameWidth, UInt32(img.width))
            XCTAssertEqual(still.frameHeight, UInt32(img.height))
        }
    }

    /// No silent fix: a timestamp that does not increase is the app's error to see, nothing is
    /// tracked, and the stream goes on; `reset()` starts the clock again (a restarted camera).
    func testANonIncreasingTimestampThrowsAndResetAcceptsAnEarlierOne() throws {
        let (buf, d) = sampleFrame(try sample(), .gray8)
        let t = try FaceTracker(options: options(.video))
        let first = try XCTUnwrap(t.detectForVideo(bytes: buf, desc: d, timestampMs: 100).faces.first)
        for ts: Int64 in [100, 99, -5] {
            let msg = assertInvalidTimestamp(try t.detectForVideo(bytes: buf, desc: d, timestampMs: ts), "\(ts) ms")
            XCTAssertTrue(msg?.contains("increasing") == true, msg ?? "")
        }
        assertInvalidTimestamp(try t.detectForVideo(bytes: buf, desc: d, timestampMs: .max), "out of range")
        let next = try XCTUnwrap(t.detectForVideo(bytes: buf, desc: d, timestampMs: 133).faces.first)
        XCTAssertEqual(next.state, .tracked, "the refused frames left the track alone")
        XCTAssertEqual(next.id, first.id)
        t.reset()
        XCTAssertEqual(try t.detectForVideo(bytes: buf, desc: d, timestampMs: 5).faces.first?.state, .detected)
    }

    /// Each running mode has its call; another mode's, and any call after `shutdown()`, is
    /// `InvalidState`. `reset()` works in every mode.
    func testEachRunningModeTakesItsOwnCall() throws {
        let (buf, d) = sampleFrame(try sample(), .gray8)
        let tap = PlanePoint(uMm: 1, vMm: 1)
        let stills = try FaceTracker(options: FaceTrackerOptions())
        XCTAssertEqual(try stills.detect(bytes: buf, desc: d).faces.count, 1)
        assertInvalidState(try stills.detectForVideo(bytes: buf, desc: d, timestampMs: 1), "video call on stills")
        assertInvalidState(try stills.detectAsync(bytes: buf, desc: d, timestampMs: 1), "live call on stills")
        assertInvalidState(try stills.addCalibrationPoint(targetId: "phone", point: tap, timestampMs: 1), "tap on stills")
        stills.reset()
        XCTAssertEqual(try stills.detect(bytes: buf, desc: d).faces.count, 1)
        let video = try FaceTracker(options: options(.video))
        assertInvalidState(try video.detect(bytes: buf, desc: d), "still call on video")
        assertInvalidState(try video.detectAsync(bytes: buf, desc: d, timestampMs: 1), "live call on video")
        video.shutdown()
        video.shutdown()
        assertInvalidState(try video.detectForVideo(bytes: buf, desc: d, timestampMs: 1), "after shutdown")
        assertInvalidState(try video.setGazeTargets(targets: []), "targets after shutdown")
        video.reset()
        video.resetGazeCalibration()
        // A listener belongs to the live stream, which needs one.
        assertInvalidConfig(try FaceTracker(options: options(.liveStream)), "a live stream without a listener")
        assertInvalidConfig(try FaceTracker(options: options(.video), listener: LiveEvents()), "a listener on video")
    }

    /// The transform is the pose as a matrix; `openglTransform` flips its y and z rows and columns.
    func testTransformIsThePoseAndOpenglTransformFlipsYAndZ() throws {
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        let f = try XCTUnwrap(FaceTracker(options: options(.video)).detectForVideo(bytes: buf, desc: d, timestampMs: 1)
            .faces.first)
        let m = try XCTUnwrap(f.transform)
        XCTAssertEqual(m.count, 16)
        for r in 0..<3 {
            for c in 0..<3 { XCTAssertEqual(m[4 * r + c], f.pose.rotation[3 * r + c], "R[\(r)][\(c)]") }
        }
        let t = f.pose.translationMm
        XCTAssertEqual([m[3], m[7], m[11]], [t.x, t.y, t.z])
        XCTAssertEqual(Array(m[12...]), [0, 0, 0, 1])
        // F·M·F with F = diag(1, −1, −1, 1): entry (r, c) changes sign when exactly one of r and c
        // is y or z.
        let sign: [Double] = [1, -1, -1, 1]
        let gl = try openglTransform(transform: m)
        XCTAssertEqual(gl.count, 16)
        for r in 0..<4 {
            for c in 0..<4 { XCTAssertEqual(gl[4 * r + c], sign[r] * sign[c] * m[4 * r + c], "(\(r), \(c))") }
        }
        let shifted: [Double] = [1, 0, 0, 7, 0, 1, 0, 8, 0, 0, 1, 9, 0, 0, 0, 1]
        let moved = try openglTransform(transform: shifted)
        XCTAssertEqual([moved[3], moved[7], moved[11]], [7, -8, -9])
        XCTAssertEqual([moved[0], moved[5], moved[10], moved[15]], [1, 1, 1, 1])
        assertInvalidConfig(try openglTransform(transform: Array(shifted.prefix(15))))
    }

    func testEyesAreOpenOnTheSampleFace() throws {
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        let f = try XCTUnwrap(FaceTracker(options: FaceTrackerOptions()).detect(bytes: buf, desc: d).faces.first)
        let eyes = try XCTUnwrap(f.eyes)
        XCTAssertGreaterThan(eyes.leftOpen, 0.5, "\(eyes)")
        XCTAssertGreaterThan(eyes.rightOpen, 0.5, "\(eyes)")
        XCTAssertLessThanOrEqual(max(eyes.leftOpen, eyes.rightOpen), 1)
    }

    func testQualityNamesWhatIsWrongAndThePoseSaysHowSureItIs() throws {
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        let t = try FaceTracker(options: options(.video))
        let r = try t.detectForVideo(bytes: buf, desc: d, timestampMs: 1)
        let f = try XCTUnwrap(r.faces.first)
        XCTAssertGreaterThanOrEqual(f.quality.score, 0.5, "a well lit, sharp, frontal face: \(f.quality)")
        XCTAssertEqual(f.quality.reasons, [])
        XCTAssertEqual(r.reasons, [])
        let u = f.uncertainty
        for sd in [u.yawDeg, u.pitchDeg, u.rollDeg] { XCTAssertTrue(sd > 0 && sd < 20, "angle sd \(sd)") }
        XCTAssertTrue(u.translationMm.z > 0 && u.translationMm.z < 200, "depth sd \(u.translationMm.z)")
        // The same frame in a dark room: the face goes, and the frame says why.
        var bytes = [UInt8](buf)
        for i in bytes.indices where i % 4 != 3 { bytes[i] >>= 4 }
        let r2 = try t.detectForVideo(bytes: Data(bytes), desc: d, timestampMs: 2)
        XCTAssertTrue(r2.reasons.contains(.dark), "dark frame: \(r2.reasons)")
        if let dark = r2.faces.first {
            XCTAssertTrue(dark.quality.reasons.contains(.dark), "\(dark.quality)")
        } else {
            XCTAssertTrue(r2.reasons.contains(.noFace) && r2.reasons.contains(.lost), "\(r2.reasons)")
        }
        // The thresholds are the app's: a stricter size bar calls the same face small.
        var strict = options(.video)
        strict.tuning = TrackerTuning(quality: QualityThresholds(minFacePx: 4000))
        let s = try FaceTracker(options: strict).detectForVideo(bytes: buf, desc: d, timestampMs: 1)
        XCTAssertEqual(try XCTUnwrap(s.faces.first).quality.reasons, [.small])
        let fit = try fitLandmarks(landmarks: exampleLandmarks(0), width: 640, height: 480, camera: nil, method: .msbp)
        XCTAssertTrue(fit.uncertainty.yawDeg > 0 && fit.uncertainty.yawDeg < 10, "\(fit.uncertainty)")
    }

    func testAModelBundleRoundTripTracksAsTheBuiltinModelsAndDamageIsTyped() throws {
        let url = FileManager.default.temporaryDirectory.appendingPathComponent("monotrack-\(getpid()).mtb")
        try Data(ModelBundle.builtin().toBytes()).write(to: url)
        defer { try? FileManager.default.removeItem(at: url) }
        let bundle = try ModelBundle.fromPath(path: url.path)
        XCTAssertEqual(bundle.formatVersion(), 1)
        XCTAssertTrue(bundle.fileNames().contains("face_model.json"))
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        let own = try FaceTracker(options: FaceTrackerOptions(models: bundle)).detect(bytes: buf, desc: d)
        let builtin = try FaceTracker(options: FaceTrackerOptions()).detect(bytes: buf, desc: d)
        XCTAssertEqual(own.faces, builtin.faces)
        var bytes = ModelBundle.builtin().toBytes()
        bytes[bytes.count / 2] ^= 1
        XCTAssertThrowsError(try ModelBundle.fromBytes(bytes: bytes)) { e in
            guard case MonotrackError.BundleChecksum = e else { return XCTFail("\(e)") }
        }
        var newer = ModelBundle.builtin().toBytes()
        newer[8] = 9
        XCTAssertThrowsError(try ModelBundle.fromBytes(bytes: newer)) { e in
            guard case MonotrackError.BundleVersion = e else { return XCTFail("\(e)") }
        }
        XCTAssertThrowsError(try ModelBundle.fromPath(path: "/nonexistent/models.mtb")) { e in
            guard case MonotrackError.ModelLoad = e else { return XCTFail("\(e)") }
        }
    }

    func testMirrorAverageIsTheStillsDefaultAndATrackerSetting() throws {
        XCTAssertNil(FaceTrackerOptions().tuning.mirrorAverage)
        let img = try sample()
        let (buf, d) = sampleFrame(img, .rgba8)
        func landmarks(_ mirrorAverage: Bool?) throws -> [Point2] {
            let t = try FaceTracker(options: with(FaceTrackerOptions()) { $0.tuning.mirrorAverage = mirrorAverage })
            XCTAssertEqual(t.options().tuning.mirrorAverage, mirrorAverage)
            return try XCTUnwrap(t.detect(bytes: buf, desc: d).faces.first).landmarks
        }
        let byDefault = try landmarks(nil)
        let plain = try landmarks(false)
        let averaged = try landmarks(true)
        // Stills are mirror-averaged unless the options say otherwise.
        XCTAssertEqual(averaged, byDefault)
        let moved = zip(plain, averaged).map { hypot($0.x - $1.x, $0.y - $1.y) }.max() ?? 0
        // The mode moves points, by less than the nets' own error on a ~100 px face.
        XCTAssertTrue(moved > 0.01 && moved < 10, "largest move \(moved) px")
    }

    func testUltraLightTrackerFollowsTheFaceWithoutLandmarkNetworks() throws {
        XCTAssertFalse(FaceTrackerOptions().tuning.ultraLight)
        let t = try FaceTracker(options: ultraLightFaceTrackerOptions(runningMode: .video))
        XCTAssertTrue(t.options().tuning.ultraLight)
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        for ts in Int64(1)...3 {
            let faces = try t.detectForVideo(bytes: buf, desc: d, timestampMs: ts * 33).faces
            XCTAssertEqual(faces.count, 1)
            let f = try XCTUnwrap(faces.first)
            let confidence = try XCTUnwrap(f.landmarkConfidence, "the ultra-light mode says which points it measured")
            XCTAssertEqual(confidence.count, 68)
            let measured = confidence.filter { $0 > 0 }.count
            XCTAssertTrue((20...27).contains(measured), "\(measured) points measured")
            // The nose tip lies inside the astronaut's face box, as in the full pipeline.
            let nose = f.landmarks[30]
            XCTAssertTrue((176...273).contains(nose.x) && (88...181).contains(nose.y), "nose at \(nose)")
            // No networks, so no gestures, gaze, action units or eyelids.
            XCTAssertTrue(f.gestures == nil && f.gaze == nil && f.pointOfGaze == nil && f.actionUnits == nil)
            XCTAssertNil(f.eyes)
        }
    }

    func testOutputTogglesLeaveTheirFieldsOut() throws {
        let img = try sample()
        let (buf, d) = sampleFrame(img, .rgba8)
        let lean = with(options(.video)) {
            $0.outputGestures = false
            $0.outputGaze = false
            $0.outputActionUnits = false
            $0.outputFacialTransformationMatrixes = false
        }
        let t = try FaceTracker(options: lean)
        let f = try XCTUnwrap(t.detectForVideo(bytes: buf, desc: d, timestampMs: 1).faces.first)
        XCTAssertTrue(f.gestures == nil && f.gaze == nil && f.pointOfGaze == nil && f.actionUnits == nil)
        XCTAssertNil(f.transform)
        XCTAssertNotNil(f.eyes, "the eyes come from the landmarks, which stay")
        XCTAssertEqual(f.landmarks.count, 68)
        assertInvalidConfig(try t.addCalibrationPoint(targetId: "phone", point: PlanePoint(uMm: 1, vMm: 1), timestampMs: 1))
        let full = try FaceTracker(options: options(.video))
        let r = try full.detectForVideo(bytes: buf, desc: d, timestampMs: 1)
        let g = try XCTUnwrap(r.faces.first)
        XCTAssertTrue(g.gestures != nil && g.gaze != nil && g.pointOfGaze != nil && g.actionUnits != nil)
        XCTAssertNotNil(g.transform)
        // The SDK's overlay rules and the wrapper's helpers on a real face.
        let arrows = try gazeArrows(landmarks: g.landmarks, gaze: try XCTUnwrap(g.gaze), lengthPx: 40)
        XCTAssertTrue(arrows.right.from.x < arrows.left.from.x, "the subject's right eye is on the image's left")
        assertInvalidConfig(try gazeArrows(landmarks: Array(g.landmarks.prefix(5)), gaze: try XCTUnwrap(g.gaze), lengthPx: 40))
        XCTAssertEqual(g.landmarkPoints.count, 68)
        XCTAssertEqual(g.landmarkPoints[30], g.landmarks[30].cgPoint)
        XCTAssertTrue(["smile", "kiss", "neutral"].contains(try XCTUnwrap(g.gestures).mouth.name))
        XCTAssertTrue(["raise", "frown", "neutral"].contains(try XCTUnwrap(g.gestures).brows.name))
        let axes = try XCTUnwrap(try headAxes(pose: g.pose, camera: r.camera, lengthMm: 50))
        XCTAssertEqual(axes.origin, projectPoint(camera: r.camera, pointMm: g.pose.translationMm))
        // The model's vertices overlay the landmarks through the result's camera (within the
        // fit's error, as the Rust test bounds it).
        var se: Float = 0
        for (v, l) in zip(g.verticesMm, g.landmarks) {
            let p = try XCTUnwrap(projectPoint(camera: r.camera, pointMm: v))
            se += (p.x - l.x) * (p.x - l.x) + (p.y - l.y) * (p.y - l.y)
        }
        XCTAssertLessThan((se / 68).squareRoot(), 8, "vertices vs landmarks, px")
    }

    func testBadTrackerOptionsRaiseInvalidConfig() {
        assertInvalidConfig(try FaceTracker(options: with(FaceTrackerOptions()) { $0.numFaces = 0 }))
        assertInvalidConfig(try FaceTracker(options: with(options(.video)) { $0.tuning.minFaceSizePx = 2 }))
        for score: Float in [.nan, -0.1, 1.5] {
            assertInvalidConfig(try FaceTracker(options: with(FaceTrackerOptions()) { $0.minFaceDetectionConfidence = score }),
                                "score \(score)")
        }
        assertInvalidConfig(try FaceTracker(options: with(FaceTrackerOptions()) { $0.minTrackingConfidence = .nan }))
    }

    func testSmallFacesOperatingPointFindsTheSampleFace() throws {
        XCTAssertEqual(FaceTrackerOptions().minFaceDetectionConfidence, 0.4)
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        let small = with(FaceTrackerOptions()) { $0.tuning.minFaceSizePx = 16; $0.minFaceDetectionConfidence = 0.25 }
        let t = try FaceTracker(options: small)
        XCTAssertEqual(t.options().minFaceDetectionConfidence, 0.25)
        let faces = try t.detect(bytes: buf, desc: d).faces
        XCTAssertFalse(faces.isEmpty, "the sample face is found at the small-faces point")
        // The best-ranked face is the astronaut's (face check and detector score both high).
        XCTAssertGreaterThan(faces.first?.bbox.width ?? 0, 60)
    }

    func testBenchmarkReportsEveryStage() throws {
        let (buf, d) = sampleFrame(try sample(), .rgba8)
        let r = try runBenchmark(bytes: buf, desc: d, iterations: 3)
        XCTAssertEqual(r.iterations, 3)
        XCTAssertEqual(r.faces, 1, "the frame's face was measured")
        XCTAssertEqual(r.stages.count, 21)
        func median(_ name: String) -> Double { r.stages.first { $0.name == name }?.medianUs ?? 0 }
        XCTAssertGreaterThan(median("tracking/landmarks"), 0, "a face was tracked")
        XCTAssertGreaterThan(median("tracking_mirror_average/landmarks"), 0)
        XCTAssertGreaterThan(median("redetect/detect"), 0)
        XCTAssertEqual(r.table.split(separator: "\n").count, 22)
    }

    func testBodyTrackerFitsTheExampleSequence() throws {
        // examples/body_fit_example.jsonl: a synthetic walk seen by a 760 px camera, 4 floor corners
        // of a 2 x 3 m rectangle, exact 2D joints and the true 3D joints in the floor's frame.
        let lines = try jsonLines("examples/body_fit_example.jsonl")
        let floor = try XCTUnwrap(lines.first?["floor"] as? [String: Any])
        let corners = points2(floor["corners_px"])
        let size = doubles(floor["size_mm"])
        let cal = try calibrateFloorCamera(cornersPx: corners, widthMm: size[0], depthMm: size[1],
                                           imageWidth: 640, imageHeight: 480, intrinsics: nil)
        XCTAssertEqual(cal.camera.intrinsics.fx, 760, accuracy: 8)
        XCTAssertLessThan(cal.rmsPx, 0.5)
        XCTAssertEqual(defaultBodyTrackerConfig().priorWeightPx, 5)
        XCTAssertFalse(defaultBodyTrackerConfig().fullModel)
        // The walker's joints carry 0.5 px of noise: a prior weight to match (the default, 5 px,
        // is made for keypoint detectors). Both body models: the reduced one and the full 54-DoF one.
        for full in [false, true] {
            var config = defaultBodyTrackerConfig()
            config.dimensionFrames = 3
            config.priorWeightPx = 0.5
            config.fullModel = full
            let t = try BodyTracker(camera: cal.camera, config: config)
            for (k, line) in lines.enumerated() {
                let named = try XCTUnwrap(line["joints2d"] as? [String: Any])
                var input: [BodyJoint2d] = []
                for (name, p) in named {
                    let xy: [Double] = doubles(p)
                    let joint = try XCTUnwrap(jointNames.firstIndex(of: name).map { joints[$0] }, name)
                    input.append(BodyJoint2d(joint: joint, position: Point2(x: Float(xy[0]), y: Float(xy[1]))))
                }
                let r = try t.fit(joints: input)
                XCTAssertEqual(r.joints.count, 15)
                XCTAssertEqual(r.dimensionsEstimated, k >= 2, "frame \(k)")
                // Before the dimensions are estimated the mean adult, smaller than the walker, is
                // fitted, so the first frames get a looser bound.
                XCTAssertLessThan(r.reprojectionRmsPx, k >= 2 ? 2 : 5, "full \(full) frame \(k)")
                if k >= 2 {
                    let truth = try XCTUnwrap((line["truth"] as? [String: Any])?["joints3d_mm"] as? [String: Any])
                    var sum = 0.0
                    for j in r.joints {
                        let p: [Double] = doubles(truth[jointNames[joints.firstIndex(of: j.joint)!]])
                        let (dx, dy, dz) = (j.positionMm.x - p[0], j.positionMm.y - p[1], j.positionMm.z - p[2])
                        sum += (dx * dx + dy * dy + dz * dz).squareRoot()
                    }
                    let err = sum / Double(r.joints.count)
                    // A wrong fit is off by metres; the bound leaves room above the CLI's own error.
                    XCTAssertLessThan(err, 120, "full \(full) frame \(k) mean joint error \(err) mm")
                }
            }
            assertInvalidConfig(try t.fit(joints: []))
        }
        assertInvalidConfig(try calibrateFloorCamera(cornersPx: Array(corners.prefix(3)), widthMm: size[0], depthMm: size[1],
                                                     imageWidth: 640, imageHeight: 480, intrinsics: nil))
        var zeroFrames = defaultBodyTrackerConfig()
        zeroFrames.dimensionFrames = 0
        assertInvalidConfig(try BodyTracker(camera: cal.camera, config: zeroFrames))
        var nanPrior = defaultBodyTrackerConfig()
        nanPrior.priorWeightPx = .nan
        assertInvalidConfig(try BodyTracker(camera: cal.camera, config: nanPrior))
    }
}
