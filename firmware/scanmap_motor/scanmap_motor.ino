// scanmap_motor: the motor controller of the scanmap rotating laser-line scanner.
//
// Turns the scanner head with a DC motor on an H-bridge (L298N, TB6612FNG) or a stepper on
// a step/dir driver (A4988, DRV8825), speaking the line protocol of
// docs/motor_protocol.md (version 1) over USB serial at 115200 baud. The head's angle is
// read by the camera from the encoder disk, not here: this board only turns the head,
// ramps it up gently, stops it on request, and brakes it by itself when the host has
// been silent for longer than the watchdog. Wiring: firmware/README.md.
//
// Board: Arduino Uno / Nano (ATmega328P) or any Arduino-compatible board.

#include <Arduino.h>

// ---- configuration -------------------------------------------------------------------
#define DRIVE_DC 1    // DC motor through an H-bridge
#define DRIVE_STEP 2  // stepper through a step/dir driver
#ifndef DRIVE
#define DRIVE DRIVE_DC
#endif

const long BAUD = 115200;
const char FIRMWARE_VERSION[] = "1.0.0";
const int PROTOCOL = 1;

// DC (H-bridge): PWM on an enable pin, direction on two inputs.
//   L298N: ENA -> PIN_PWM (remove the ENA jumper), IN1 -> PIN_IN1, IN2 -> PIN_IN2.
//   TB6612FNG: PWMA -> PIN_PWM, AIN1 -> PIN_IN1, AIN2 -> PIN_IN2, STBY -> PIN_STBY.
const uint8_t PIN_PWM = 9;
const uint8_t PIN_IN1 = 7;
const uint8_t PIN_IN2 = 8;
const uint8_t PIN_STBY = 6;
// Step/dir driver (A4988, DRV8825): STEP, DIR, and ENABLE (active low).
const uint8_t PIN_STEP = 3;
const uint8_t PIN_DIR = 4;
const uint8_t PIN_ENABLE = 5;
const uint16_t MAX_STEP_RATE = 3200;  // steps/s at speed 1000 (200 steps x 16 microsteps / s)
// Optional driver fault input (DRV8825 nFAULT, or an over-current comparator), active low.
const bool USE_FAULT_PIN = false;
const uint8_t PIN_FAULT = 2;

const int SPEED_MAX = 1000;
const long RAMP_PER_SECOND = 2000;  // per mille per second: full speed in 0.5 s
const unsigned int WATCHDOG_DEFAULT_MS = 1000;
const unsigned int WATCHDOG_MIN_MS = 100;
const unsigned int WATCHDOG_MAX_MS = 5000;
const uint8_t MAX_REQUEST = 63;  // characters before LF

// ---- state ---------------------------------------------------------------------------
enum State { STATE_STOP, STATE_BRAKE, STATE_RUN };
const uint8_t FAULT_WATCHDOG = 1;
const uint8_t FAULT_DRIVER = 2;

State state = STATE_STOP;
bool clockwise = false;
int target = 0;            // requested speed, per mille
long appliedMilli = 0;     // applied signed speed, per mille x 1000 (CCW positive)
uint8_t faults = 0;
unsigned int watchdogMs = WATCHDOG_DEFAULT_MS;
unsigned long lastRequestMs = 0;
unsigned long lastTickMs = 0;
unsigned long lastStepUs = 0;

char rx[MAX_REQUEST + 2];
uint8_t rxLength = 0;
bool discarding = false;

// ---- replies: printed as they are built, with the running XOR checksum ------------------
uint8_t outSum = 0;

void outChar(char c) {
  Serial.write(c);
  outSum ^= (uint8_t)c;
}

void outText(const char *text) {
  while (*text) outChar(*text++);
}

void outNumber(long value) {
  char digits[12];
  ltoa(value, digits, 10);
  outText(digits);
}

void outBegin(long tag) {
  outSum = 0;
  if (tag >= 0) {
    outChar('#');
    outNumber(tag);
    outChar(' ');
  }
}

void outEnd() {
  const char hex[] = "0123456789ABCDEF";
  uint8_t sum = outSum;
  Serial.write('*');
  Serial.write(hex[sum >> 4]);
  Serial.write(hex[sum & 15]);
  Serial.write('\n');
}

void outFaults() {
  if (!faults) {
    outText("NONE");
    return;
  }
  bool first = true;
  if (faults & FAULT_WATCHDOG) {
    outText("WATCHDOG");
    first = false;
  }
  if (faults & FAULT_DRIVER) {
    if (!first) outChar(',');
    outText("DRIVER");
  }
}

void outIdentity() {
  outText("scanmap-motor proto=");
  outNumber(PROTOCOL);
  outText(" fw=");
  outText(FIRMWARE_VERSION);
  outText(DRIVE == DRIVE_DC ? " drive=dc" : " drive=step");
}

// ---- the motor outputs ---------------------------------------------------------------
void applyOutputs() {
  long applied = appliedMilli / 1000;
  bool ccw = applied >= 0;
#if DRIVE == DRIVE_DC
  long magnitude = ccw ? applied : -applied;
  digitalWrite(PIN_STBY, HIGH);
  if (state == STATE_BRAKE) {  // short brake: both low-side switches on
    digitalWrite(PIN_IN1, HIGH);
    digitalWrite(PIN_IN2, HIGH);
    analogWrite(PIN_PWM, 255);
  } else if (state == STATE_STOP || magnitude == 0) {  // coast: outputs off
    digitalWrite(PIN_IN1, LOW);
    digitalWrite(PIN_IN2, LOW);
    analogWrite(PIN_PWM, 0);
  } else {
    digitalWrite(PIN_IN1, ccw ? HIGH : LOW);
    digitalWrite(PIN_IN2, ccw ? LOW : HIGH);
    analogWrite(PIN_PWM, (int)(magnitude * 255 / SPEED_MAX));
  }
#else
  digitalWrite(PIN_DIR, ccw ? HIGH : LOW);
  // STOP disables the driver (the head turns freely); BRAKE and RUN hold torque.
  digitalWrite(PIN_ENABLE, state == STATE_STOP ? HIGH : LOW);
#endif
}

void halt(State how) {
  state = how;
  target = 0;
  appliedMilli = 0;
  applyOutputs();
}

void raiseFault(uint8_t fault, State how, const char *name) {
  halt(how);
  faults |= fault;
  outBegin(-1);
  outText("! FAULT ");
  outText(name);
  outEnd();
}

// ---- requests ------------------------------------------------------------------------
bool parseNumber(const char *text, long low, long high, long *value) {
  if (!*text) return false;
  long result = 0;
  for (const char *p = text; *p; ++p) {
    if (*p < '0' || *p > '9' || result > high) return false;
    result = result * 10 + (*p - '0');
  }
  if (result < low || result > high) return false;
  *value = result;
  return true;
}

// Splits `line` in place into at most `most` words; returns how many.
uint8_t splitWords(char *line, char **words, uint8_t most) {
  uint8_t count = 0;
  char *p = line;
  while (*p) {
    while (*p == ' ') *p++ = '\0';
    if (!*p) break;
    if (count == most) return most + 1;
    words[count++] = p;
    while (*p && *p != ' ') ++p;
  }
  return count;
}

void replyError(long tag, const char *code, const char *detail) {
  outBegin(tag);
  outText("ERR ");
  outText(code);
  outChar(' ');
  outText(detail);
  outEnd();
}

void execute(long tag, char *body) {
  char *words[4];
  uint8_t count = splitWords(body, words, 3);
  if (count == 0) return;
  lastRequestMs = millis();
  const char *name = words[0];
  uint8_t args = count - 1;
  if (!strcmp(name, "HELLO") && args == 0) {
    halt(STATE_STOP);
    faults = 0;
    outBegin(tag);
    outText("OK HELLO ");
    outIdentity();
    outText(" watchdog=");
    outNumber(watchdogMs);
    outEnd();
  } else if (!strcmp(name, "RUN") && args == 2) {
    long speed;
    bool ccw = !strcmp(words[1], "CCW");
    if ((!ccw && strcmp(words[1], "CW")) || !parseNumber(words[2], 0, SPEED_MAX, &speed)) {
      replyError(tag, "ARGS", "RUN <CCW|CW> <0..1000>");
      return;
    }
    if (faults) {
      outBegin(tag);
      outText("ERR FAULT ");
      outFaults();
      outEnd();
      return;
    }
    if (state != STATE_RUN) appliedMilli = 0;
    state = STATE_RUN;
    clockwise = !ccw;
    target = (int)speed;
    applyOutputs();
    outBegin(tag);
    outText("OK RUN dir=");
    outText(ccw ? "CCW" : "CW");
    outText(" speed=");
    outNumber(target);
    outEnd();
  } else if ((!strcmp(name, "STOP") || !strcmp(name, "BRAKE")) && args == 0) {
    bool brake = name[0] == 'B';
    halt(brake ? STATE_BRAKE : STATE_STOP);
    outBegin(tag);
    outText(brake ? "OK BRAKE" : "OK STOP");
    outEnd();
  } else if (!strcmp(name, "STATUS") && args == 0) {
    long applied = appliedMilli / 1000;
    outBegin(tag);
    outText("OK STATUS state=");
    outText(state == STATE_RUN ? "RUN" : state == STATE_BRAKE ? "BRAKE" : "STOP");
    outText(clockwise ? " dir=CW speed=" : " dir=CCW speed=");
    outNumber(applied < 0 ? -applied : applied);
    outText(" target=");
    outNumber(target);
    outText(" faults=");
    outFaults();
    outText(" t=");
    outNumber((long)millis());
    outEnd();
  } else if (!strcmp(name, "PING") && args == 0) {
    outBegin(tag);
    outText("OK PING t=");
    outNumber((long)millis());
    outEnd();
  } else if (!strcmp(name, "WATCHDOG") && args == 1) {
    long ms;
    if (!parseNumber(words[1], WATCHDOG_MIN_MS, WATCHDOG_MAX_MS, &ms)) {
      replyError(tag, "ARGS", "WATCHDOG <100..5000>");
      return;
    }
    watchdogMs = (unsigned int)ms;
    outBegin(tag);
    outText("OK WATCHDOG ms=");
    outNumber(watchdogMs);
    outEnd();
  } else if (!strcmp(name, "CLEAR") && args == 0) {
    faults = 0;
    outBegin(tag);
    outText("OK CLEAR");
    outEnd();
  } else if (!strcmp(name, "HELLO") || !strcmp(name, "RUN") || !strcmp(name, "STOP") ||
             !strcmp(name, "BRAKE") || !strcmp(name, "STATUS") || !strcmp(name, "PING") ||
             !strcmp(name, "WATCHDOG") || !strcmp(name, "CLEAR")) {
    replyError(tag, "ARGS", "wrong number of arguments");
  } else {
    outBegin(tag);
    outText("ERR UNKNOWN ");
    outText(name);
    outEnd();
  }
}

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

// One received line (without LF): check bytes and checksum, take the tag, execute.
void handleLine(char *line, uint8_t length) {
  if (length && line[length - 1] == '\r') line[--length] = '\0';
  uint8_t sum = 0;
  for (uint8_t i = 0; i < length; ++i) {
    if (line[i] < 0x20 || line[i] > 0x7E) {
      replyError(-1, "BAD_BYTE", "byte outside printable ASCII");
      return;
    }
  }
  char *star = strrchr(line, '*');
  if (star) {
    *star = '\0';
    for (char *p = line; *p; ++p) sum ^= (uint8_t)*p;
    int high = hexValue(star[1]), low = high >= 0 ? hexValue(star[2]) : -1;
    if (low < 0 || star[3] != '\0' || ((high << 4) | low) != sum) {
      replyError(-1, "CHECKSUM", "mismatch");
      return;
    }
  }
  long tag = -1;
  char *body = line;
  if (line[0] == '#') {
    char *space = strchr(line, ' ');
    if (space) *space = '\0';
    if (!space || !parseNumber(line + 1, 0, 65535, &tag)) {
      replyError(-1, "ARGS", "bad tag");
      return;
    }
    body = space + 1;
  }
  execute(tag, body);
}

void readSerial() {
  while (Serial.available() > 0) {
    char c = (char)Serial.read();
    if (c == '\n') {
      if (discarding) {
        discarding = false;
        replyError(-1, "TOO_LONG", "line over 63 characters");
      } else if (rxLength) {
        rx[rxLength] = '\0';
        handleLine(rx, rxLength);
      }
      rxLength = 0;
    } else if (!discarding) {
      if (rxLength > MAX_REQUEST) {  // one more than 63: a CR may precede the LF
        discarding = true;
        rxLength = 0;
      } else {
        rx[rxLength++] = c;
      }
    }
  }
}

// ---- ramp, watchdog, steps -----------------------------------------------------------
void tick() {
  unsigned long now = millis();
  unsigned long elapsed = now - lastTickMs;
  if (elapsed == 0) return;
  lastTickMs = now;
  if (state == STATE_RUN && now - lastRequestMs > watchdogMs) {
    raiseFault(FAULT_WATCHDOG, STATE_BRAKE, "WATCHDOG");
    return;
  }
  if (USE_FAULT_PIN && digitalRead(PIN_FAULT) == LOW && !(faults & FAULT_DRIVER)) {
    raiseFault(FAULT_DRIVER, STATE_STOP, "DRIVER");
    return;
  }
  if (state != STATE_RUN) return;
  long goal = (clockwise ? -1L : 1L) * target * 1000L;
  long step = RAMP_PER_SECOND * (long)elapsed;  // per mille x 1000 per ms elapsed
  long before = appliedMilli;
  if (appliedMilli < goal) appliedMilli = min(goal, appliedMilli + step);
  if (appliedMilli > goal) appliedMilli = max(goal, appliedMilli - step);
  if (appliedMilli / 1000 != before / 1000) applyOutputs();
}

void stepPulses() {
#if DRIVE == DRIVE_STEP
  long applied = appliedMilli / 1000;
  if (state != STATE_RUN || applied == 0) return;
  unsigned long rate = (unsigned long)(applied < 0 ? -applied : applied) * MAX_STEP_RATE / SPEED_MAX;
  unsigned long interval = 1000000UL / (rate ? rate : 1);
  unsigned long now = micros();
  if (now - lastStepUs >= interval) {
    // Keep to the schedule: restarting it at `now` would add the loop's latency (~0.1 ms
    // on an ATmega328P) to every step, 24 % slow at 3200 steps/s. After a pause, restart.
    lastStepUs = now - lastStepUs >= 2 * interval ? now : lastStepUs + interval;
    digitalWrite(PIN_STEP, HIGH);
    delayMicroseconds(2);
    digitalWrite(PIN_STEP, LOW);
  }
#endif
}

void setup() {
#if DRIVE == DRIVE_DC
  pinMode(PIN_PWM, OUTPUT);
  pinMode(PIN_IN1, OUTPUT);
  pinMode(PIN_IN2, OUTPUT);
  pinMode(PIN_STBY, OUTPUT);
#else
  pinMode(PIN_STEP, OUTPUT);
  pinMode(PIN_DIR, OUTPUT);
  pinMode(PIN_ENABLE, OUTPUT);
#endif
  if (USE_FAULT_PIN) pinMode(PIN_FAULT, INPUT_PULLUP);
  halt(STATE_STOP);
  Serial.begin(BAUD);
  outBegin(-1);
  outText("! BOOT ");
  outIdentity();
  outEnd();
  lastTickMs = lastRequestMs = millis();
}

void loop() {
  readSerial();
  tick();
  stepPulses();
}
