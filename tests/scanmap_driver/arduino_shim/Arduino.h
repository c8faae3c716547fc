// A host stand-in for the Arduino core, enough to run firmware/scanmap_motor on Linux for
// tests: Serial is stdin/stdout (a pseudo-terminal), the clock is CLOCK_MONOTONIC, and
// every change of a pin is written to stderr as "t=<ms> <D|A><pin>=<value>".
#pragma once
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define HIGH 1
#define LOW 0
#define INPUT 0
#define OUTPUT 1
#define INPUT_PULLUP 2

unsigned long millis();
unsigned long micros();
void pinMode(uint8_t pin, uint8_t mode);
void digitalWrite(uint8_t pin, uint8_t value);
int digitalRead(uint8_t pin);
void analogWrite(uint8_t pin, int value);
void delayMicroseconds(unsigned int us);
char *ltoa(long value, char *out, int base);

template <class T> T min(T a, T b) { return a < b ? a : b; }
template <class T> T max(T a, T b) { return a > b ? a : b; }

struct HostSerial {
  void begin(long baud);
  int available();
  int read();
  size_t write(uint8_t byte);
  size_t write(char c) { return write((uint8_t)c); }
};
extern HostSerial Serial;

void setup();
void loop();
