// Benchmark app: runs the SDK's runBenchmark (the desktop bench's code) on bundled images and shows
// the per-stage table (stage, median / p90 / mean ms) and the tracking vs re-detect totals per frame.
plugins {
    alias(libs.plugins.android.application)
    alias(libs.plugins.kotlin.android)
}

android {
    namespace = "io.monotrack.bench"
    compileSdk = 35

    defaultConfig {
        applicationId = "io.monotrack.bench"
        minSdk = 24
        targetSdk = 35
        versionCode = 1
        versionName = "0.1.0"
    }

    buildTypes {
        release {
            // Benchmarks are only meaningful on release native code; R8 would not change them.
            isMinifyEnabled = false
            // Debug-signed so the benchmark installs without a keystore; never ship this.
            signingConfig = signingConfigs.getByName("debug")
        }
    }

    sourceSets {
        named("main") {
            // The repository's public-domain sample images (samples/data), bundled from there as they
            // are (no copy in this app; its README.md rides along and is skipped by extension).
            assets.srcDirs("../data")
        }
    }

    testOptions {
        // BenchSummary's JVM tests (src/test) use JUnit 5, as the library's do.
        unitTests.all { it.useJUnitPlatform() }
    }

    packaging {
        jniLibs { useLegacyPackaging = false }
    }

    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }
}

kotlin { jvmToolchain(17) }

dependencies {
    implementation(project(":monotrack"))
    implementation(libs.androidx.appcompat)
    implementation(libs.androidx.core.ktx)

    // The tests build BenchReport records only; they never load the native library.
    testImplementation(libs.junit.jupiter)
    testRuntimeOnly(libs.junit.platform.launcher)
}
