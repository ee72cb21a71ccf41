// swift-tools-version:5.9
// The monotrack Swift package: the uniffi-generated Swift (module MonotrackFFI, generated into
// Sources/MonotrackFFI by build-xcframework.sh) over the Rust static library in
// MonotrackFFIFFI.xcframework (also built by that script), plus the idiomatic wrapper module
// Monotrack (CVPixelBuffer → frame, orientation, the generated FaceTracker's CMSampleBuffer calls,
// LiveEvents). Apps depend on the "Monotrack" product.
import PackageDescription

let package = Package(
    name: "Monotrack",
    platforms: [
        // 15: Swift concurrency back-deployment and SwiftUI Canvas in the samples; the Rust library
        // itself is built for iOS 13+ (rustc's aarch64-apple-ios default deployment target is 10.0).
        .iOS(.v15),
    ],
    products: [
        .library(name: "Monotrack", targets: ["Monotrack"]),
    ],
    targets: [
        // Static library + C header + module map "MonotrackFFIFFI" per platform slice.
        .binaryTarget(name: "MonotrackFFIFFI", path: "MonotrackFFIFFI.xcframework"),
        // uniffi's generated Swift (MonotrackFFI.swift), not committed.
        .target(
            name: "MonotrackFFI",
            dependencies: ["MonotrackFFIFFI"],
            path: "Sources/MonotrackFFI",
            exclude: ["README.md"]
        ),
        .target(
            name: "Monotrack",
            dependencies: ["MonotrackFFI"],
            path: "Sources/Monotrack",
            linkerSettings: [
                .linkedFramework("CoreVideo"),
                .linkedFramework("AVFoundation"),
                .linkedFramework("ImageIO"),
            ]
        ),
        .testTarget(
            name: "MonotrackTests",
            dependencies: ["Monotrack"],
            path: "Tests/MonotrackTests"
        ),
    ]
)
