// The microphone as the recogniser wants it: 16 kHz mono 16-bit PCM in 20 ms frames.
// Runs on the audio thread: averages the channels, averages each group of input samples
// that makes one output sample (a box filter, enough for speech below 8 kHz), and posts
// every full frame with its level (RMS, 0..1) to the page.
"use strict";

const FRAME = 320; // samples at 16 kHz: 20 ms

class Capture extends AudioWorkletProcessor {
  constructor() {
    super();
    this.step = sampleRate / 16000; // input samples per output sample
    this.position = 0; // where the next output sample ends, in input samples
    this.sum = 0;
    this.count = 0;
    this.frame = new Int16Array(FRAME);
    this.filled = 0;
    this.energy = 0;
  }

  process(inputs) {
    const input = inputs[0];
    if (!input || input.length === 0) return true;
    const length = input[0].length;
    for (let i = 0; i < length; i += 1) {
      let value = 0;
      for (let c = 0; c < input.length; c += 1) value += input[c][i];
      this.sum += value / input.length;
      this.count += 1;
      this.position += 1;
      if (this.position >= this.step) {
        this.position -= this.step;
        const sample = Math.max(-1, Math.min(1, this.sum / this.count));
        this.sum = 0;
        this.count = 0;
        this.frame[this.filled] = sample < 0 ? sample * 32768 : sample * 32767;
        this.energy += sample * sample;
        this.filled += 1;
        if (this.filled === FRAME) {
          const level = Math.sqrt(this.energy / FRAME);
          this.port.postMessage({ pcm: this.frame.buffer, level }, [this.frame.buffer]);
          this.frame = new Int16Array(FRAME);
          this.filled = 0;
          this.energy = 0;
        }
      }
    }
    return true;
  }
}

registerProcessor("capture", Capture);
