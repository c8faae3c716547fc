// uart_pty_runner: run an ATmega328P firmware (ELF) in simavr, in real time, with UART0
// bridged to a pseudo-terminal and the scanmap motor pins reported on stderr.
//
//   uart_pty_runner [-p] [-m MCU] [-f HZ] firmware.elf
//
// UART0 is bridged to stdin/stdout (give it the master side of a pty, as the tests do);
// with -p the runner opens a pty itself and prints "port <path>" on stdout, for a serial
// terminal (e.g. `python -m serial.tools.miniterm <path> 115200`).
//
// Pins, as "t=<ms> <pin>=<value>" lines on stderr whenever one changes (t is simulated
// time): D2..D8 (PD2..PD7, PB0) as 0/1, and A9, the duty 0..255 on D9 (OC1A, timer 1)
// as analogWrite() would set it: OCR1A while the compare output is connected (COM1A1 in
// TCCR1A), else the port bit. Other lines on stderr are simavr's own messages.
//
// simavr runs much faster than 16 MHz; the runner sleeps whenever simulated time gets
// ahead of the wall clock, so millis() in the firmware keeps pace with the host's clock
// (it may fall behind on an overloaded machine, never run ahead by more than ~1 ms).
// Single-threaded: bytes from the pty enter the UART between instructions, honouring
// simavr's XON/XOFF (its receive FIFO), so nothing is lost.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_ioport.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_elf.h"
#include "sim_irq.h"

enum { SERVICE_US = 100, MAX_AHEAD_US = 1000 };
// ATmega328P data-space addresses of the registers behind D9 (OC1A = PB1).
enum { REG_DDRB = 0x24, REG_PORTB = 0x25, REG_TCCR1A = 0x80, REG_OCR1AL = 0x88,
       REG_OCR1AH = 0x89, BIT_COM1A1 = 7, BIT_PB1 = 1 };

static avr_t *avr;
static int in_fd = 0, out_fd = 1;
static int xon = 1;  // simavr's UART FIFO has room (XOFF when it is full)
static avr_irq_t *uart_in;
static uint8_t rx[256], tx[4096];
static size_t rx_start, rx_end, tx_length;
static int pin_value[16];  // last reported value + 1 (0: never reported)

static double sim_ms(void) { return avr->cycle * 1e3 / avr->frequency; }

static uint64_t wall_us(void) {
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  return (uint64_t)now.tv_sec * 1000000u + (uint64_t)now.tv_nsec / 1000u;
}

static void report(char kind, int pin, int value) {
  int slot = kind == 'A' ? 15 : pin;
  if (pin_value[slot] == value + 1) return;
  pin_value[slot] = value + 1;
  fprintf(stderr, "t=%.0f %c%d=%d\n", sim_ms(), kind, pin, value);
}

static void pin_changed(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  report('D', (int)(intptr_t)param, value ? 1 : 0);
}

static void report_pwm(void) {
  const uint8_t *d = avr->data;
  if (!(d[REG_DDRB] & (1 << BIT_PB1))) return;  // not an output yet
  int duty = (d[REG_TCCR1A] & (1 << BIT_COM1A1)) ? (d[REG_OCR1AH] << 8 | d[REG_OCR1AL])
                                                 : ((d[REG_PORTB] >> BIT_PB1) & 1) * 255;
  report('A', 9, duty);
}

static void uart_byte_out(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)param;
  if (tx_length < sizeof tx) tx[tx_length++] = (uint8_t)value;
}

static void uart_xon(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)value, (void)param;
  xon = 1;
}

static void uart_xoff(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)value, (void)param;
  xon = 0;
}

static void flush_tx(void) {
  if (!tx_length) return;
  ssize_t n = write(out_fd, tx, tx_length);
  if (n < 0 && errno == EAGAIN) return;  // the host is slow: keep the bytes
  if (n <= 0) n = (ssize_t)tx_length;    // no host on the pty: lost, as on a board
  memmove(tx, tx + n, tx_length - (size_t)n);
  tx_length -= (size_t)n;
}

static void feed_rx(void) {
  while (xon && rx_start < rx_end) avr_raise_irq(uart_in, rx[rx_start++]);
}

// Waits up to `us` for input from the host (sleeping the whole time if there is none,
// e.g. while no host has the pty open), then reads what came.
static void wait_input(uint64_t us) {
  struct pollfd p = {.fd = in_fd, .events = POLLIN};
  int ready = poll(&p, 1, (int)(us / 1000));
  if (ready > 0 && !(p.revents & POLLIN)) {  // hung up: poll returns at once
    struct timespec pause = {0, (long)(us % 1000000u) * 1000};
    nanosleep(&pause, NULL);
    return;
  }
  if (ready <= 0 || rx_start < rx_end) return;
  ssize_t n = read(in_fd, rx, sizeof rx);
  rx_start = 0;
  rx_end = n > 0 ? (size_t)n : 0;
}

static void logger(avr_t *a, const int level, const char *format, va_list ap) {
  if (level > (a ? a->log : LOG_ERROR)) return;
  fputs("simavr: ", stderr);
  vfprintf(stderr, format, ap);
}

static int open_own_pty(void) {
  int master, slave;
  char name[256];
  struct termios raw;
  cfmakeraw(&raw);
  if (openpty(&master, &slave, name, &raw, NULL) < 0) return -1;
  printf("port %s\n", name);
  fflush(stdout);
  // The slave stays open here, so the pty keeps its raw settings between hosts.
  return master;
}

int main(int argc, char **argv) {
  const char *mcu = "atmega328p";
  uint32_t frequency = 16000000;
  int own_pty = 0, opt;
  while ((opt = getopt(argc, argv, "pm:f:")) != -1) {
    if (opt == 'p') own_pty = 1;
    else if (opt == 'm') mcu = optarg;
    else if (opt == 'f') frequency = (uint32_t)strtoul(optarg, NULL, 10);
    else goto usage;
  }
  if (optind != argc - 1) {
  usage:
    fprintf(stderr, "usage: %s [-p] [-m mcu] [-f hz] firmware.elf\n", argv[0]);
    return 2;
  }
  prctl(PR_SET_PDEATHSIG, SIGTERM);  // never outlive the test (or shell) that started us
  setvbuf(stderr, NULL, _IOLBF, 0);
  avr_global_logger_set(logger);
  elf_firmware_t firmware;
  memset(&firmware, 0, sizeof firmware);
  if (elf_read_firmware(argv[optind], &firmware) != 0) {
    fprintf(stderr, "cannot read %s\n", argv[optind]);
    return 1;
  }
  snprintf(firmware.mmcu, sizeof firmware.mmcu, "%s", mcu);
  firmware.frequency = frequency;
  avr = avr_make_mcu_by_name(mcu);
  if (!avr) {
    fprintf(stderr, "simavr knows no MCU %s\n", mcu);
    return 1;
  }
  avr_init(avr);
  avr->log = LOG_ERROR;
  avr_load_firmware(avr, &firmware);

  if (own_pty && (in_fd = out_fd = open_own_pty()) < 0) {
    perror("openpty");
    return 1;
  }
  fcntl(in_fd, F_SETFL, fcntl(in_fd, F_GETFL) | O_NONBLOCK);
  fcntl(out_fd, F_SETFL, fcntl(out_fd, F_GETFL) | O_NONBLOCK);

  uint32_t flags = 0;  // no echo of the UART on simavr's console
  avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                          uart_byte_out, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                          uart_xon, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                          uart_xoff, NULL);
  for (int pin = 2; pin <= 8; ++pin) {
    char port = pin < 8 ? 'D' : 'B';
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(port), pin % 8),
                            pin_changed, (void *)(intptr_t)pin);
    report('D', pin, 0);  // every pin reads low after reset
  }

  const avr_cycle_count_t service = (avr_cycle_count_t)frequency / (1000000 / SERVICE_US);
  avr_cycle_count_t next_service = 0;
  uint64_t start = wall_us();
  for (;;) {
    int state = avr_run(avr);
    if (state == cpu_Done || state == cpu_Crashed) {
      fprintf(stderr, "simavr: the firmware %s at t=%.0f ms\n",
              state == cpu_Done ? "stopped" : "crashed", sim_ms());
      return state == cpu_Done ? 0 : 1;
    }
    if (avr->cycle < next_service) continue;
    next_service = avr->cycle + service;
    report_pwm();
    flush_tx();
    feed_rx();
    uint64_t simulated = (uint64_t)(sim_ms() * 1000.0), elapsed = wall_us() - start;
    if (simulated > elapsed + MAX_AHEAD_US) wait_input(simulated - elapsed);
    else if (rx_start == rx_end) wait_input(0);
  }
}
