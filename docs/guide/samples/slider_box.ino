// facepuppet slider box: six slide potentiometers on A0..A5, sent as one ASCII line per reading
// ("512,300,1023,0,77,1000"). facepuppet's serial backend reads it with protocol=ascii, and the
// shipped arduino_sliders mapping names the values box.ch0 .. box.ch5 (0..1023).

const uint8_t PINS[] = {A0, A1, A2, A3, A4, A5};
const uint8_t COUNT = sizeof(PINS) / sizeof(PINS[0]);
const unsigned long PERIOD_US = 5000;  // 200 readings a second

void setup() {
  Serial.begin(115200);  // the URL's baudrate (115200 is the default)
}

void loop() {
  static unsigned long next = micros();
  if ((long)(micros() - next) < 0) return;  // wait for the next reading's time
  next += PERIOD_US;
  for (uint8_t i = 0; i < COUNT; i++) {
    if (i > 0) Serial.print(',');
    Serial.print(analogRead(PINS[i]));
  }
  Serial.println();  // CR LF ends the reading
}
