/** The xTool session's timing rules: polls, the liveness window and its slow-link rule, re-checks. */

/**
 * Poll intervals: every 3 s while a job is loaded or running (issue 4), and every 3 s when idle
 * too (issue 15: it was 10 s). The status frames are rare, so the poll is the laser's liveness, and
 * a silent link must show as down within 5 s; two small reads every 3 s is what the ESP32 already
 * answers while it runs a job, and the gateway shares them among viewers (sharing.ts).
 */
export const POLL_BUSY_MS = 3000;
export const POLL_IDLE_MS = 3000;
/**
 * The liveness window: nothing heard from the laser for this long (a poll every 3 s, each of its
 * answers counts) is a silent link, shown as down at once, without waiting for the request's own
 * timeout (client.ts READ_TIMEOUT_MS). While the page is hidden the poll runs every 10 s or more,
 * and the window grows with it.
 */
export const LIVENESS_MS = 4000;
/**
 * A slow link that still delivers is not silence: the window is at least the poll period and this
 * many times the slowest of the last answers (SLOW_ANSWERS of them), so answers that take 4 s (2 s
 * latency each way) or 8 s (and a new connection per request) keep the link online. It is back to
 * LIVENESS_MS a few answers after the link is fast again.
 */
export const SLOW_ANSWER_FACTOR = 1.5;
export const SLOW_ANSWERS = 4;
/**
 * A laser that answered, whole, that it is not a D-series is asked again on this backoff (from
 * 5 s up to a minute): the verdict is re-checked, never final (a swapped or re-flashed device).
 */
export const RECHECK_BASE_MS = 5000;
export const RECHECK_MAX_MS = 60_000;
/**
 * The status socket's heartbeat policy. The laser speaks on :8081 only when its state changes
 * (nothing on connect, no ping it answers), so silence proves nothing either way: a healthy
 * socket of an idle laser and a dead TCP connection (the laser was switched off and on, the WiFi
 * dropped) look the same. A socket quiet this long is reopened; the polls keep the state meanwhile.
 */
export const SOCKET_QUIET_MS = 5 * 60_000;
