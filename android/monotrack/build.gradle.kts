// The monotrack Android library (AAR): the uniffi-generated Kotlin (io.monotrack, generated into
// build/generated/uniffi by ../build-native.sh), the native libraries per ABI (src/main/jniLibs, also
// from build-native.sh) and the idiomatic wrappers (io.monotrack.android).
plugins {
    alias(libs.plugins.android.library)
    alias(libs.plugins.kotlin.android)
}

android {
    namespace = "io.monotrack.android"
    compileSdk = 35

    defaultConfig {
        // 24 (Android 7.0): not a toolchain limit (Rust's std and CameraX support 21+) but a
        // support choice: Java 8 library APIs without core-library desugaring, and no 2014-era
        // devices too slow for real-time tracking. Must equal MIN_SDK in ../build-native.sh.
        minSdk = 24
        consumerProguardFiles("consumer-rules.pro")
        ndk {
            abiFilters += listOf("arm64-v8a", "armeabi-v7a", "x86_64")
        }
    }

    sourceSets {
        named("main") {
            // jvmMain: wrapper logic without android.* imports (also compiled by the JVM tests).
            java.srcDirs("src/jvmMain/kotlin", "build/generated/uniffi")
        }
        named("test") {
            java.srcDirs("src/jvmTest/kotlin")
        }
    }

    packaging {
        jniLibs {
            // Keep .so files uncompressed and page-aligned in the APK so they are mapped in place
            // (needed for 16 KB page devices; also smaller installs).
            useLegacyPackaging = false
        }
    }

    compileOptions {
        sourceCompatibility = JavaVersion.VERSION_17
        targetCompatibility = JavaVersion.VERSION_17
    }

    testOptions {
        unitTests.all { it.useJUnitPlatform() }
    }
}

kotlin {
    // Not explicitApi(): it would also apply to the generated bindings compiled in this module. The
    // wrappers spell out `public` anyway.
    jvmToolchain(17)
}

dependencies {
    // api: apps see JNA only through the generated code, but it must be on their classpath. The AAR
    // (not the jar) carries libjnidispatch.so for each Android ABI.
    api(libs.jna) { artifact { type = "aar" } }
    api(libs.androidx.camera.core)
    // Camera2 interop: the device's lens calibration for the SDK's intrinsics.
    implementation(libs.androidx.camera.camera2)

    // The JVM tests touch only the generated records and the wrappers' pure logic, never native code.
    testImplementation(libs.junit.jupiter)
    testRuntimeOnly(libs.junit.platform.launcher)
}

// Cross-builds the native libraries and generates the Kotlin bindings (../build-native.sh). Skip with
// -Pmonotrack.skipNative=true when jniLibs and build/generated/uniffi are already in place (CI caches).
val buildNative by tasks.registering(Exec::class) {
    description = "cargo ndk build of monotrack-ffi + uniffi Kotlin generation"
    group = "build"
    workingDir = rootDir
    commandLine("bash", "${rootDir}/build-native.sh")
    inputs.dir("${rootDir}/../core/src")
    inputs.dir("${rootDir}/../bindings/src")
    outputs.dir("src/main/jniLibs")
    outputs.dir("build/generated/uniffi")
    onlyIf { !providers.gradleProperty("monotrack.skipNative").map(String::toBoolean).getOrElse(false) }
}

tasks.named("preBuild") { dependsOn(buildNative) }
