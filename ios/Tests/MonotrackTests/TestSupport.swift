// What the tests against the real library share: the repository's files, the committed public-domain
// sample image samples/data/astronaut.jpg (as the Kotlin JVM tests in bindings/tests/kotlin use it)
// and frames packed from it in every pixel format with padded strides.
#if canImport(ImageIO)
import CoreGraphics
import ImageIO
#endif
import Foundation
import XCTest
@testable import Monotrack

/// The repository: $MONOTRACK_ROOT (bindings/tests/run-swift.sh sets it), else three folders above
/// this file (ios/Tests/MonotrackTests).
let repoRoot: URL = {
    if let r = ProcessInfo.processInfo.environment["MONOTRACK_ROOT"], !r.isEmpty {
        return URL(fileURLWithPath: r)
    }
    return URL(fileURLWithPath: #filePath).deletingLastPathComponent().deletingLastPathComponent()
        .deletingLastPathComponent().deletingLastPathComponent()
}()

func repoFile(_ path: String) throws -> String {
    try String(contentsOf: repoRoot.appendingPathComponent(path), encoding: .utf8)
}

/// An RGB image, 3 bytes per pixel, rows packed.
struct RGBImage {
    let width: Int
    let height: Int
    let rgb: [UInt8]

    func pixel(_ x: Int, _ y: Int) -> (r: Int, g: Int, b: Int) {
        let o = (y * width + x) * 3
        return (Int(rgb[o]), Int(rgb[o + 1]), Int(rgb[o + 2]))
    }

    func luma(_ x: Int, _ y: Int) -> UInt8 {
        let p = pixel(x, y)
        return sdkLuma(p.r, p.g, p.b)
    }
}

/// The SDK's documented luma: BT.601 full range in 8-bit fixed point.
func sdkLuma(_ r: Int, _ g: Int, _ b: Int) -> UInt8 {
    UInt8((77 * r + 150 * g + 29 * b + 128) >> 8)
}

enum SampleError: Error, CustomStringConvertible {
    case unreadable(String)
    var description: String { if case .unreadable(let m) = self { return m }; return "" }
}

/// Reads a binary PPM (P6, maxval 255), as `djpeg -pnm` writes it.
func readPPM(_ url: URL) throws -> RGBImage {
    let d = [UInt8](try Data(contentsOf: url))
    var i = 0
    func token() throws -> String {
        while i < d.count {
            if d[i] == UInt8(ascii: "#") {
                while i < d.count, d[i] != 0x0A { i += 1 }
            } else if d[i] == 0x20 || d[i] == 0x0A || d[i] == 0x0D || d[i] == 0x09 {
                i += 1
            } else { break }
        }
        let start = i
        while i < d.count, !(d[i] == 0x20 || d[i] == 0x0A || d[i] == 0x0D || d[i] == 0x09) { i += 1 }
        return String(decoding: d[start..<i], as: UTF8.self)
    }
    guard try token() == "P6", let w = Int(try token()), let h = Int(try token()), try token() == "255",
          d.count - (i + 1) >= w * h * 3
    else { throw SampleError.unreadable("\(url.path) is not an 8-bit P6 PPM") }
    return RGBImage(width: w, height: h, rgb: Array(d[(i + 1)..<(i + 1 + w * h * 3)]))
}

/// The sample image: $MONOTRACK_SAMPLE_PPM (the JPEG decoded by run-swift.sh: Foundation on Linux
/// decodes no images), else the JPEG itself through ImageIO.
func loadSample() throws -> RGBImage {
    if let p = ProcessInfo.processInfo.environment["MONOTRACK_SAMPLE_PPM"], !p.isEmpty {
        return try readPPM(URL(fileURLWithPath: p))
    }
    let url = repoRoot.appendingPathComponent("samples/data/astronaut.jpg")
    #if canImport(ImageIO)
    guard let src = CGImageSourceCreateWithURL(url as CFURL, nil),
          let img = CGImageSourceCreateImageAtIndex(src, 0, nil)
    else { throw SampleError.unreadable("cannot decode \(url.path)") }
    let (w, h) = (img.width, img.height)
    var rgba = [UInt8](repeating: 0, count: w * h * 4)
    let drawn: Bool = rgba.withUnsafeMutableBytes { buf in
        guard let ctx = CGContext(data: buf.baseAddress, width: w, height: h, bitsPerComponent: 8,
                                  bytesPerRow: w * 4, space: CGColorSpaceCreateDeviceRGB(),
                                  bitmapInfo: CGImageAlphaInfo.noneSkipLast.rawValue)
        else { return false }
        ctx.draw(img, in: CGRect(x: 0, y: 0, width: w, height: h))
        return true
    }
    guard drawn else { throw SampleError.unreadable("cannot draw \(url.path)") }
    var rgb = [UInt8](repeating: 0, count: w * h * 3)
    for p in 0..<(w * h) {
        rgb[3 * p] = rgba[4 * p]; rgb[3 * p + 1] = rgba[4 * p + 1]; rgb[3 * p + 2] = rgba[4 * p + 2]
    }
    return RGBImage(width: w, height: h, rgb: rgb)
    #else
    throw SampleError.unreadable("set MONOTRACK_SAMPLE_PPM to \(url.path) as PPM (djpeg -pnm): no ImageIO here")
    #endif
}

private let sampleResult: Result<RGBImage, Error> = Result { try loadSample() }

/// The sample image, decoded once.
func sample() throws -> RGBImage { try sampleResult.get() }

/// Padding added to every row stride, so a stride bug cannot go unnoticed.
let pad = 24

/// Reference upright luma of the sample after a clockwise rotation by `rot`, then optional mirroring.
func reference(_ img: RGBImage, rot: Int, mirrored: Bool) -> (width: Int, height: Int, pixels: [UInt8]) {
    let (w, h) = (img.width, img.height)
    let (ow, oh) = rot % 180 == 0 ? (w, h) : (h, w)
    var out = [UInt8](repeating: 0, count: ow * oh)
    for y in 0..<h {
        for x in 0..<w {
            var (ox, oy): (Int, Int)
            switch rot {
            case 0: (ox, oy) = (x, y)
            case 90: (ox, oy) = (h - 1 - y, x)
            case 180: (ox, oy) = (w - 1 - x, h - 1 - y)
            default: (ox, oy) = (y, w - 1 - x)
            }
            if mirrored { ox = ow - 1 - ox }
            out[oy * ow + ox] = img.luma(x, y)
        }
    }
    return (ow, oh, out)
}

/// A frame of the sample in `format` (every `PixelFormat`), rows `pad` bytes longer than needed and
/// the last row short; YUV chroma is flat grey (only luma is read, the whole layout is checked).
func sampleFrame(_ img: RGBImage, _ format: PixelFormat, rot: UInt32 = 0, mirrored: Bool = false)
    -> (bytes: Data, desc: FrameDesc)
{
    let (w, h) = (img.width, img.height)
    let chromaRows = (h + 1) / 2
    func packed(_ bpp: Int, _ put: (inout [UInt8], Int, (r: Int, g: Int, b: Int)) -> Void) -> (Data, FrameDesc) {
        let stride = w * bpp + pad
        var b = [UInt8](repeating: 0, count: stride * (h - 1) + w * bpp)
        for y in 0..<h { for x in 0..<w { put(&b, y * stride + x * bpp, img.pixel(x, y)) } }
        return (Data(b), FrameDesc(width: UInt32(w), height: UInt32(h), format: format, rowStride: UInt32(stride),
                                   uvRowStride: 0, uvPixelStride: 0, rotationDegrees: rot, mirrored: mirrored))
    }
    func yuv(uvRowStride: Int, uvPixelStride: Int, chromaBytes: Int) -> (Data, FrameDesc) {
        let stride = w + pad
        var b = [UInt8](repeating: 128, count: stride * h + chromaBytes)
        for y in 0..<h { for x in 0..<w { b[y * stride + x] = img.luma(x, y) } }
        return (Data(b), FrameDesc(width: UInt32(w), height: UInt32(h), format: format, rowStride: UInt32(stride),
                                   uvRowStride: UInt32(uvRowStride), uvPixelStride: UInt32(uvPixelStride),
                                   rotationDegrees: rot, mirrored: mirrored))
    }
    switch format {
    case .rgba8: return packed(4) { b, o, p in b[o] = UInt8(p.r); b[o + 1] = UInt8(p.g); b[o + 2] = UInt8(p.b); b[o + 3] = 255 }
    case .bgra8: return packed(4) { b, o, p in b[o] = UInt8(p.b); b[o + 1] = UInt8(p.g); b[o + 2] = UInt8(p.r); b[o + 3] = 255 }
    case .rgb8: return packed(3) { b, o, p in b[o] = UInt8(p.r); b[o + 1] = UInt8(p.g); b[o + 2] = UInt8(p.b) }
    case .gray8: return packed(1) { b, o, p in b[o] = sdkLuma(p.r, p.g, p.b) }
    case .nv21, .nv12:
        let s = w + pad
        return yuv(uvRowStride: s, uvPixelStride: 2, chromaBytes: s * chromaRows)
    case .i420:
        let s = (w + 1) / 2 + pad / 2
        return yuv(uvRowStride: s, uvPixelStride: 1, chromaBytes: 2 * s * chromaRows)
    }
}

/// A tightly packed 8-bit gray frame.
func grayFrame(_ pixels: [UInt8], width: Int, height: Int, rot: UInt32 = 0, mirrored: Bool = false)
    -> (bytes: Data, desc: FrameDesc)
{
    (Data(pixels), FrameDesc(width: UInt32(width), height: UInt32(height), format: .gray8, rowStride: UInt32(width),
                             uvRowStride: 0, uvPixelStride: 0, rotationDegrees: rot, mirrored: mirrored))
}

/// The NV21 buffer of a sensor mounted at 90°: the sample turned by 270°, so the frame's rotation 90
/// makes it upright again (faces reach the SDK upright, as a camera app's would).
func nv21SensorFrame(_ img: RGBImage) -> (bytes: Data, desc: FrameDesc) {
    let (w, h, pixels) = reference(img, rot: 270, mirrored: false)
    let stride = w + pad
    var b = [UInt8](repeating: 128, count: stride * h + stride * ((h + 1) / 2))
    for y in 0..<h { for x in 0..<w { b[y * stride + x] = pixels[y * w + x] } }
    return (Data(b), FrameDesc(width: UInt32(w), height: UInt32(h), format: .nv21, rowStride: UInt32(stride),
                               uvRowStride: UInt32(stride), uvPixelStride: 2, rotationDegrees: 90, mirrored: false))
}

/// `desc` with other fields.
func with(_ desc: FrameDesc, _ change: (inout FrameDesc) -> Void) -> FrameDesc {
    var d = desc
    change(&d)
    return d
}

/// `options` with other fields.
func with(_ options: FaceTrackerOptions, _ change: (inout FaceTrackerOptions) -> Void) -> FaceTrackerOptions {
    var o = options
    change(&o)
    return o
}

/// The default options in `mode`.
func options(_ mode: RunningMode) -> FaceTrackerOptions {
    FaceTrackerOptions(runningMode: mode)
}

/// The line's JSON object.
func jsonObject(_ line: Substring) throws -> [String: Any] {
    guard let o = try JSONSerialization.jsonObject(with: Data(line.utf8)) as? [String: Any] else {
        throw SampleError.unreadable("not a JSON object: \(line.prefix(60))")
    }
    return o
}

/// The non-blank lines of a JSON-lines file of the repository, parsed.
func jsonLines(_ path: String) throws -> [[String: Any]] {
    try repoFile(path).split(separator: "\n").filter { !$0.allSatisfy(\.isWhitespace) }.map(jsonObject)
}

/// Numbers of a JSON array of numbers (`[1, 2.5]`).
func doubles(_ v: Any?) -> [Double] {
    (v as? [Any] ?? []).compactMap { ($0 as? NSNumber)?.doubleValue }
}

/// Asserts that `body` throws `MonotrackError.InvalidFrame`; returns its message.
@discardableResult
func assertInvalidFrame<T>(_ body: @autoclosure () throws -> T, _ what: String = "",
                           file: StaticString = #filePath, line: UInt = #line) -> String? {
    do {
        _ = try body()
        XCTFail("no error: expected InvalidFrame \(what)", file: file, line: line)
    } catch MonotrackError.InvalidFrame(let msg) {
        return msg
    } catch {
        XCTFail("\(error): expected InvalidFrame \(what)", file: file, line: line)
    }
    return nil
}

/// Asserts that `body` throws `MonotrackError.InvalidConfig`; returns its message.
@discardableResult
func assertInvalidConfig<T>(_ body: @autoclosure () throws -> T, _ what: String = "",
                            file: StaticString = #filePath, line: UInt = #line) -> String? {
    do {
        _ = try body()
        XCTFail("no error: expected InvalidConfig \(what)", file: file, line: line)
    } catch MonotrackError.InvalidConfig(let msg) {
        return msg
    } catch {
        XCTFail("\(error): expected InvalidConfig \(what)", file: file, line: line)
    }
    return nil
}

/// Asserts that `body` throws `MonotrackError.InvalidTimestamp`; returns its message.
@discardableResult
func assertInvalidTimestamp<T>(_ body: @autoclosure () throws -> T, _ what: String = "",
                               file: StaticString = #filePath, line: UInt = #line) -> String? {
    do {
        _ = try body()
        XCTFail("no error: expected InvalidTimestamp \(what)", file: file, line: line)
    } catch MonotrackError.InvalidTimestamp(let msg) {
        return msg
    } catch {
        XCTFail("\(error): expected InvalidTimestamp \(what)", file: file, line: line)
    }
    return nil
}

/// Asserts that `body` throws `MonotrackError.InvalidState`; returns its message.
@discardableResult
func assertInvalidState<T>(_ body: @autoclosure () throws -> T, _ what: String = "",
                           file: StaticString = #filePath, line: UInt = #line) -> String? {
    do {
        _ = try body()
        XCTFail("no error: expected InvalidState \(what)", file: file, line: line)
    } catch MonotrackError.InvalidState(let msg) {
        return msg
    } catch {
        XCTFail("\(error): expected InvalidState \(what)", file: file, line: line)
    }
    return nil
}
