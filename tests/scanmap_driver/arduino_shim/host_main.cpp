// The host side of the Arduino stand-in (see Arduino.h).
#include "Arduino.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/prctl.h>
#include <time.h>
#include <unistd.h>

HostSerial Serial;
static unsigned char rxBuffer[512];
static int rxStart = 0, rxEnd = 0;
static char txBuffer[4096];
static int txLength = 0;
static int pinState[64];
static struct timespec started;

static double elapsedSeconds() {
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  return (now.tv_sec - started.tv_sec) + 1e-9 * (now.tv_nsec - started.tv_nsec);
}

unsigned long millis() { return (unsigned long)(elapsedSeconds() * 1e3); }
unsigned long micros() { return (unsigned long)(elapsedSeconds() * 1e6); }
void delayMicroseconds(unsigned int) {}

static void logPin(char kind, uint8_t pin, int value) {
  if (pinState[pin] == value + 1) return;
  pinState[pin] = value + 1;
  fprintf(stderr, "t=%lu %c%d=%d\n", millis(), kind, pin, value);
}

void pinMode(uint8_t, uint8_t) {}
void digitalWrite(uint8_t pin, uint8_t value) { logPin('D', pin, value); }
void analogWrite(uint8_t pin, int value) { logPin('A', pin, value); }
int digitalRead(uint8_t) { return HIGH; }

char *ltoa(long value, char *out, int) {
  sprintf(out, "%ld", value);
  return out;
}

void HostSerial::begin(long) {}

int HostSerial::available() {
  if (rxStart == rxEnd) {
    rxStart = rxEnd = 0;
    ssize_t got = ::read(0, rxBuffer, sizeof rxBuffer);
    if (got > 0) rxEnd = (int)got;  // EAGAIN, or EIO while no host has the port open
  }
  return rxEnd - rxStart;
}

int HostSerial::read() { return available() ? rxBuffer[rxStart++] : -1; }

size_t HostSerial::write(uint8_t byte) {
  if (txLength < (int)sizeof txBuffer) txBuffer[txLength++] = (char)byte;
  return 1;
}

static void flushSerial() {
  int sent = 0;
  while (sent < txLength) {
    ssize_t n = ::write(1, txBuffer + sent, txLength - sent);
    if (n <= 0) break;  // no host: the bytes are lost, as on a real board
    sent += (int)n;
  }
  txLength = 0;
}

int main() {
  prctl(PR_SET_PDEATHSIG, SIGTERM);  // never outlive the test that started us
  clock_gettime(CLOCK_MONOTONIC, &started);
  setvbuf(stderr, NULL, _IOLBF, 0);
  fcntl(0, F_SETFL, fcntl(0, F_GETFL) | O_NONBLOCK);
  fcntl(1, F_SETFL, fcntl(1, F_GETFL) | O_NONBLOCK);
  setup();
  for (;;) {
    loop();
    flushSerial();
    usleep(200);
  }
}
