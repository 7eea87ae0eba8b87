#!/bin/sh
# Builds the ffmpeg and ffprobe that the container ships: Debian's ffmpeg
# source (`apt-get source ffmpeg`, with Debian's patches), configured with
# --disable-everything and only the components amc uses, linked statically
# against its own libav* so that the runtime needs nothing but the few
# external codec libraries named below.
#
#   cd ffmpeg-5.1.x && sh build-ffmpeg.sh /opt/ffmpeg   # -> /opt/ffmpeg/bin/{ffmpeg,ffprobe}
#
# Build dependencies (Debian): build-essential nasm pkg-config libx264-dev
# libvpx-dev libopus-dev libdav1d-dev libsrt-gnutls-dev libvidstab-dev
# libgnutls28-dev zlib1g-dev.
# Runtime libraries: libx264-164 libvpx7 libopus0 libdav1d6 libsrt1.5-gnutls
# libvidstab1.1 (libgnutls30, libstdc++6 and zlib1g are already in
# debian:bookworm-slim).
#
# What amc asks of ffmpeg (amc-video/src: ffmpeg.rs, probe.rs, caps.rs,
# images.rs) and so what is enabled here:
#   - ffprobe of the input; ffmpeg decoding its video stream to raw frames on a
#     pipe (`-f rawvideo -pix_fmt yuv420p|rgb24 pipe:1`) through showinfo (frame
#     timestamps), scale (range/bit depth/chroma conversion), and the filters
#     ffmpeg inserts by itself: null/anull, format/aformat, aresample, trim/atrim
#     (-t), transpose/hflip/vflip/rotate (phone videos' rotation);
#   - the output: frames piped in as Matroska (rawvideo), encoded by libx264
#     (.mp4, .mkv) or libvpx-vp9 (.webm), pad for odd sizes; the input's audio
#     copied (`-c:a copy`) or, where the container cannot hold it, decoded and
#     encoded to AAC (.mp4) or Opus (.webm); data tracks (GoPro gpmd) and the
#     timecode copied into the MP4;
#   - TIFF pictures decoded to PPM (`-f image2pipe -c:v ppm`);
#   - the live source (--live-source): files, rtsp://, rtp/udp, srt://, rtmp://,
#     http(s):// and HLS, or a V4L2 camera (--live-format v4l2).
# The decoders are those of the videos people upload (phones, action cameras,
# drones, editing exports, screen captures, older AVI/MPEG/WMV files); left
# out are other codecs (e.g. AV1 encoding, HEVC encoding, Cineform, Bink,
# RealVideo, most audio codecs), subtitles, hardware acceleration, devices
# other than V4L2 and every filter amc does not use.
#
# Two users besides the service: `amc compare` (an evaluation command) runs
# ffmpeg's vid.stab and deshake as peers, on clips or ffconcat lists of
# images (libvidstab, vidstabdetect/vidstabtransform/deshake, the concat
# demuxer; ~0.5 MB), and the repository's tests make their fixtures with
# ffmpeg (the lavfi device and its testsrc, testsrc2, color and sine sources,
# the select and fps filters; the encoders and muxers on the second line of
# their lists: FFV1, MPEG-4, PNG, JPEG, BMP, TIFF, WAV, AVI, raw H.264, Y4M;
# a few hundred kB), so that the tests run against this build too.
set -eu

prefix=${1:?usage: build-ffmpeg.sh PREFIX (run in the ffmpeg source directory)}

list() { printf '%s\n' "$@" | tr '\n' ',' | sed 's/,$//'; }

decoders=$(list \
    h264 hevc vp8 vp9 libdav1d mpeg4 h263 msmpeg4v2 msmpeg4v3 wmv1 wmv2 \
    mpeg1video mpeg2video \
    mjpeg prores dnxhd dvvideo vc1 wmv3 theora ffv1 huffyuv utvideo \
    png tiff bmp gif rawvideo \
    aac mp3 mp3float mp2 mp2float ac3 eac3 dca opus vorbis flac alac wmav2 \
    pcm_s16le pcm_s16be pcm_s24le pcm_s24be pcm_s32le pcm_f32le pcm_u8 \
    pcm_alaw pcm_mulaw)
encoders=$(list \
    libx264 libvpx_vp9 aac libopus rawvideo wrapped_avframe ppm \
    mpeg4 ffv1 png mjpeg bmp tiff pcm_s16le)
demuxers=$(list \
    mov matroska avi mpegts mpegps flv asf dv ogg h264 hevc m4v mpegvideo \
    mjpeg ivf obu yuv4mpegpipe rawvideo gif \
    image2 image2pipe image_png_pipe image_jpeg_pipe image_bmp_pipe image_tiff_pipe \
    wav mp3 aac ac3 flac \
    rtsp rtp sdp hls \
    concat)
muxers=$(list \
    mp4 matroska webm rawvideo image2pipe null data \
    image2 yuv4mpegpipe avi h264 wav)
parsers=$(list \
    h264 hevc vp8 vp9 av1 mpeg4video mpegvideo mjpeg png bmp gif vc1 dvdsub \
    aac aac_latm ac3 mpegaudio opus vorbis flac dca)
bsfs=$(list \
    aac_adtstoasc h264_mp4toannexb hevc_mp4toannexb vp9_superframe \
    vp9_superframe_split extract_extradata)
filters=$(list \
    showinfo scale format pad null anull aformat aresample trim atrim \
    transpose hflip vflip rotate setpts asetpts fps \
    vidstabdetect vidstabtransform deshake \
    testsrc testsrc2 color sine select)
protocols=$(list \
    file pipe tcp udp rtp http https httpproxy tls hls crypto libsrt rtmp rtmps)
indevs=$(list v4l2 lavfi)

./configure \
    --prefix="$prefix" \
    --extra-version=amc-minimal \
    --toolchain=hardened \
    --enable-gpl \
    --disable-autodetect \
    --disable-everything \
    --disable-doc \
    --disable-debug \
    --disable-ffplay \
    --disable-postproc \
    --enable-pthreads \
    --enable-zlib \
    --enable-gnutls \
    --enable-libx264 \
    --enable-libvpx \
    --enable-libopus \
    --enable-libdav1d \
    --enable-libsrt \
    --enable-libvidstab \
    --enable-decoder="$decoders" \
    --enable-encoder="$encoders" \
    --enable-demuxer="$demuxers" \
    --enable-muxer="$muxers" \
    --enable-parser="$parsers" \
    --enable-bsf="$bsfs" \
    --enable-filter="$filters" \
    --enable-protocol="$protocols" \
    --enable-indev="$indevs"

# configure ignores names it does not know: make sure every one is enabled.
check() {
    for name in $(echo "$2" | tr ',' ' '); do
        macro=$(echo "CONFIG_${name}_$1" | tr 'a-z' 'A-Z')
        grep -q "^#define $macro 1" config.h config_components.h \
            || { echo "build-ffmpeg.sh: $1 $name is not enabled" >&2; exit 1; }
    done
}
check decoder "$decoders"; check encoder "$encoders"; check demuxer "$demuxers"
check muxer "$muxers"; check parser "$parsers"; check bsf "$bsfs"
check filter "$filters"; check protocol "$protocols"; check indev "$indevs"

make -j"$(nproc)"
make install
