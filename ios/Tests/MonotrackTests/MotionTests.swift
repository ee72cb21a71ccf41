// Motion comparison through the generated Swift (the port of bindings/tests/kotlin/MotionTest.kt): a
// recorded trial and the same frames fed live to a MotionSession score alike and blame the faulty
// joint; bad input is typed.
import Foundation
import XCTest
@testable import Monotrack

private let weights = """
    {"phases": [{"name": "swing", "start_frame": 0, "end_frame": 39}],
      "features": [{"phase": "swing", "joint": "relbow", "feature": "flexion", "weight": 1},
                   {"phase": "swing", "joint": "rwrist", "feature": "linear_velocity", "weight": 1}]}
    """

/// A right-arm swing frame (phase 0...1), the elbow bent `bend` degrees more.
private func frame(_ phase: Double, bend: Double) -> MotionFrame {
    let rad = Double.pi / 180
    let th = 50 * sin(2 * .pi * phase) * rad
    let el = (30 + 25 * cos(2 * .pi * phase) + bend) * rad
    let sh = Vec3(x: -180, y: 0, z: 1380)
    let elbow = Vec3(x: sh.x, y: sh.y + 290 * sin(th), z: sh.z - 290 * cos(th))
    let wrist = Vec3(x: elbow.x, y: elbow.y + 250 * sin(th + el), z: elbow.z - 250 * cos(th + el))
    let pos: [(BodyJoint, Vec3)] = [
        (.pelvis, Vec3(x: 0, y: 0, z: 900)), (.thorax, Vec3(x: 0, y: 0, z: 1400)),
        (.lShoulder, Vec3(x: 180, y: 0, z: 1380)), (.lElbow, Vec3(x: 200, y: 0, z: 1100)),
        (.lWrist, Vec3(x: 210, y: 60, z: 860)), (.rShoulder, sh), (.rElbow, elbow),
        (.rWrist, wrist), (.lHip, Vec3(x: 100, y: 0, z: 900)), (.lKnee, Vec3(x: 100, y: 30, z: 480)),
        (.lAnkle, Vec3(x: 100, y: 0, z: 80)), (.rHip, Vec3(x: -100, y: 0, z: 900)),
        (.rKnee, Vec3(x: -100, y: 0, z: 480)), (.rAnkle, Vec3(x: -100, y: 0, z: 80)),
        (.head, Vec3(x: 0, y: 20, z: 1620)),
    ]
    return MotionFrame(joints: pos.map { BodyJoint3d(joint: $0.0, positionMm: $0.1) })
}

private func sequence(_ n: Int, bend: Double) -> [MotionFrame] {
    (0..<n).map { frame(Double($0) / Double(n - 1), bend: bend) }
}

final class MotionTests: XCTestCase {
    func testARecordedAndALiveTrialScoreAlikeAndBlameTheElbow() throws {
        let reference = sequence(40, bend: 0)
        let trial = sequence(44, bend: 25)
        let report = try compareMotion(reference: reference, trial: trial, weightsJson: weights, fps: 30)
        XCTAssertLessThan(report.overall, 0.95)
        XCTAssertEqual(report.worst.joint, .rElbow)
        XCTAssertEqual(report.worst.feature, .flexion)
        XCTAssertTrue(report.summary.contains("right elbow"), report.summary)
        XCTAssertEqual(report.path.first?.referenceFrame, 0)
        let live = try MotionSession(reference: reference, weightsJson: weights, fps: 30)
        for f in trial { _ = try live.addFrame(frame: f) }
        XCTAssertEqual(try live.finish(), report)
        assertInvalidFrame(try live.finish(), "a second finish")
        let same = try compareMotion(reference: reference, trial: reference, weightsJson: weights, fps: 30)
        XCTAssertEqual(same.overall, 1, accuracy: 1e-9)
    }

    func testBadInputIsTyped() throws {
        let reference = sequence(40, bend: 0)
        assertInvalidConfig(try compareMotion(reference: reference, trial: reference,
                                              weightsJson: weights.replacingOccurrences(of: "flexion", with: "twist"), fps: 30))
        assertInvalidConfig(try MotionSession(reference: Array(reference.prefix(20)), weightsJson: weights, fps: 30))
        let missing = MotionFrame(joints: Array(reference[0].joints.dropFirst()))
        assertInvalidConfig(try compareMotion(reference: reference, trial: [missing] + reference, weightsJson: weights, fps: 30))
    }
}
