// The containers the page reads in the browser (mediabunny's video formats):
// one list, named by the drop zone and by the message of a clip it cannot
// read. Anything else (AVI, FLV, ...) and codecs the browser cannot decode
// (HEVC in Chromium, for one) go to the server instead, which reads whatever
// ffmpeg reads.

/** The containers, as the page names them. */
export const READABLE = ['MP4', 'MOV', 'WebM', 'MKV', 'MPEG-TS'];

/** Their file extensions (the file picker's `accept`, with `video/*`). */
export const EXTENSIONS = ['.mp4', '.m4v', '.mov', '.webm', '.mkv', '.ts'];

/** "MP4, MOV, WebM, MKV or MPEG-TS". */
export const readableList = () => `${READABLE.slice(0, -1).join(', ')} or ${READABLE.at(-1)}`;
