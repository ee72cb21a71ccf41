// Pure mapping logic (no CoreVideo calls) so it is unit-testable without a camera, and builds on
// Linux too (bindings/tests/run-swift.sh): only the EXIF orientation needs ImageIO. Sizes and
// strides are checked by the SDK's own rule (`frameByteCount`), not here.
import Foundation
import MonotrackFFI
#if canImport(ImageIO)
import CoreGraphics
import ImageIO
#endif

#if !canImport(Darwin)
/// A CoreVideo pixel format code, as MacTypes' `OSType` (Linux has no MacTypes).
public typealias OSType = UInt32
#endif

/// Errors raised by the wrapper before a frame reaches the SDK. Errors from the SDK itself are
/// `MonotrackError` (invalid frame, timestamp, state or config, model load, internal).
public enum FrameError: Error, Equatable, CustomStringConvertible {
    /// The pixel buffer's format is not one the wrapper maps without converting (BGRA, NV12, gray).
    case unsupportedPixelFormat(OSType)
    /// `CVPixelBufferLockBaseAddress` failed with this status.
    case lockFailed(Int32)
    /// The locked pixel buffer has no CPU-accessible base address (e.g. a GPU-only IOSurface).
    case noBaseAddress
    /// The buffer's sizes do not fit a `FrameDesc`, or it has no image.
    case invalidLayout(String)
    /// A sample buffer without a valid presentation time, which video and live-stream tracking need.
    case noPresentationTime
    /// A rotation that is not a multiple of 90 degrees.
    case invalidRotation(Double)

    /// A one-line explanation for logs and UI.
    public var description: String {
        switch self {
        case .unsupportedPixelFormat(let f): return "unsupported pixel format \(fourCC(f))"
        case .lockFailed(let s): return "CVPixelBufferLockBaseAddress failed (\(s))"
        case .noBaseAddress: return "pixel buffer has no CPU base address"
        case .invalidLayout(let m): return "invalid frame layout: \(m)"
        case .noPresentationTime: return "sample buffer has no valid presentation time"
        case .invalidRotation(let d): return "rotation \(d)° is not a multiple of 90°"
        }
    }
}

/// The four-character code of a pixel format, for messages (`'BGRA'`, `'420f'`).
func fourCC(_ code: OSType) -> String {
    let bytes = [24, 16, 8, 0].map { UInt8((code >> $0) & 0xFF) }
    let printable = bytes.allSatisfy { $0 >= 0x20 && $0 < 0x7F }
    return printable ? "'" + String(decoding: bytes, as: UTF8.self) + "'" : String(code)
}

/// How a buffer must be turned to be upright: rotate clockwise by `rotationDegrees`, then mirror
/// left–right when `mirrored` (the SDK applies them in that order).
public struct FrameOrientation: Equatable, Sendable {
    /// Clockwise rotation making the buffer upright: 0, 90, 180 or 270.
    public let rotationDegrees: UInt32
    /// Mirror the upright image left–right (front camera, to match its mirrored preview).
    public let mirrored: Bool

    /// Largest |angle| accepted: far beyond any real rotation, far below Int's range.
    private static let maxAbsDegrees = 1e9

    /// The buffer is already upright and not mirrored.
    public static let up = FrameOrientation(uncheckedDegrees: 0, mirrored: false)

    private init(uncheckedDegrees: UInt32, mirrored: Bool) {
        self.rotationDegrees = uncheckedDegrees
        self.mirrored = mirrored
    }

    /// An orientation from a clockwise rotation in degrees (any multiple of 90, negative or ≥ 360
    /// included) and mirroring.
    ///
    /// - Throws: `FrameError.invalidRotation` when `degrees` is not a multiple of 90.
    public init(rotationDegrees degrees: Double, mirrored: Bool) throws {
        // Rotation angles from AVFoundation are exact multiples of 90; allow float noise only. The
        // magnitude bound keeps Int(quarter) from trapping on absurd input.
        guard degrees.isFinite, abs(degrees) <= Self.maxAbsDegrees else {
            throw FrameError.invalidRotation(degrees)
        }
        let quarter = (degrees / 90).rounded()
        guard abs(quarter * 90 - degrees) < 1e-6 else { throw FrameError.invalidRotation(degrees) }
        let q = ((Int(quarter) % 4) + 4) % 4
        self.init(uncheckedDegrees: UInt32(q * 90), mirrored: mirrored)
    }

    #if canImport(ImageIO)
    /// The orientation that displays an image tagged with EXIF orientation `orientation` upright
    /// (still photos, `CGImageSource` properties, Vision's convention).
    ///
    /// Derivation (rotate clockwise, then mirror the result): `.right` (EXIF 6) stores the top of the
    /// scene on the buffer's left, so 90°; `.left` (8) 270°; `.leftMirrored` (5) is the transpose,
    /// which is 90° then a mirror; `.rightMirrored` (7) the anti-transpose, 270° then a mirror.
    public init(_ orientation: CGImagePropertyOrientation) {
        switch orientation {
        case .up: self.init(uncheckedDegrees: 0, mirrored: false)
        case .upMirrored: self.init(uncheckedDegrees: 0, mirrored: true)
        case .down: self.init(uncheckedDegrees: 180, mirrored: false)
        case .downMirrored: self.init(uncheckedDegrees: 180, mirrored: true)
        case .right: self.init(uncheckedDegrees: 90, mirrored: false)
        case .rightMirrored: self.init(uncheckedDegrees: 270, mirrored: true)
        case .left: self.init(uncheckedDegrees: 270, mirrored: false)
        case .leftMirrored: self.init(uncheckedDegrees: 90, mirrored: true)
        @unknown default: self.init(uncheckedDegrees: 0, mirrored: false)
        }
    }
    #endif

    /// The orientation for a camera buffer delivered unrotated, given the clockwise angle that makes
    /// it upright: `AVCaptureDevice.RotationCoordinator.videoRotationAngleForHorizonLevelCapture`
    /// (iOS 17+), the value one would otherwise set as the connection's `videoRotationAngle`.
    /// Leaving the connection unrotated and letting the SDK rotate avoids a full-frame copy.
    ///
    /// - Parameter frontCamera: mirror results to match the (mirrored) front camera preview.
    /// - Throws: `FrameError.invalidRotation` when the angle is not a multiple of 90.
    public init(videoRotationAngle: CGFloat, frontCamera: Bool) throws {
        try self.init(rotationDegrees: Double(videoRotationAngle), mirrored: frontCamera)
    }
}

/// Pixel format codes the wrapper accepts (`kCVPixelFormatType_*` values, repeated so that this file
/// needs no CoreVideo).
enum PixelFormatCode {
    /// kCVPixelFormatType_32BGRA
    static let bgra: OSType = 0x4247_5241 // 'BGRA'
    /// kCVPixelFormatType_420YpCbCr8BiPlanarFullRange (NV12, full range): the default camera format.
    static let nv12Full: OSType = 0x3432_3066 // '420f'
    /// kCVPixelFormatType_420YpCbCr8BiPlanarVideoRange (NV12, video range).
    static let nv12Video: OSType = 0x3432_3076 // '420v'
    /// kCVPixelFormatType_OneComponent8 (8-bit gray).
    static let gray: OSType = 0x4C30_3038 // 'L008'
}

/// Which plane of a pixel buffer the SDK reads, and how.
struct PlaneChoice: Equatable {
    /// Plane index (0 for packed formats).
    let plane: Int
    /// Whether the buffer is planar (read the base address of `plane`, not of the buffer).
    let planar: Bool
    /// The SDK's format for the plane.
    let format: PixelFormat
}

enum FrameLayout {
    /// The plane and SDK format for a CoreVideo pixel format. NV12 is passed as its luma plane alone
    /// (GRAY8): the tracker uses luma only, so the chroma plane is never read.
    ///
    /// - Throws: `FrameError.unsupportedPixelFormat` for other formats.
    static func choice(for code: OSType) throws -> PlaneChoice {
        switch code {
        case PixelFormatCode.bgra: return PlaneChoice(plane: 0, planar: false, format: .bgra8)
        case PixelFormatCode.nv12Full, PixelFormatCode.nv12Video:
            return PlaneChoice(plane: 0, planar: true, format: .gray8)
        case PixelFormatCode.gray: return PlaneChoice(plane: 0, planar: false, format: .gray8)
        default: throw FrameError.unsupportedPixelFormat(code)
        }
    }

    /// Describes one plane of `width`×`height` pixels spaced `bytesPerRow` apart, and the bytes
    /// the SDK reads of it (`frameByteCount`: the last row may end right after its pixels).
    ///
    /// - Throws: `FrameError.invalidLayout` for a size a `FrameDesc` cannot hold;
    ///   `MonotrackError.InvalidFrame` for a zero size or a stride shorter than a row.
    static func describe(
        _ choice: PlaneChoice, width: Int, height: Int, bytesPerRow: Int, orientation: FrameOrientation
    ) throws -> (desc: FrameDesc, byteCount: Int) {
        guard let w = UInt32(exactly: width), let h = UInt32(exactly: height),
              let stride = UInt32(exactly: bytesPerRow)
        else { throw FrameError.invalidLayout("size \(width)x\(height), bytesPerRow \(bytesPerRow)") }
        let desc = FrameDesc(
            width: w,
            height: h,
            format: choice.format,
            rowStride: stride,
            uvRowStride: 0,
            uvPixelStride: 0,
            rotationDegrees: orientation.rotationDegrees,
            mirrored: orientation.mirrored
        )
        let count = try frameByteCount(desc: desc)
        return (desc, Int(count))
    }
}
