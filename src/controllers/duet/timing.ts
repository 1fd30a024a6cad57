/**
 * The Duet session's timing rules (README "Liveness"). Through the console server a PING is
 * answered by the server itself, which pings DSF and closes every page socket (1011) after 4.5 s
 * of silence. Updates may pause (the protocol document says so): silence without a PING is not death.
 */

/** `PING\n` after this long without a frame. */
export const PING_AFTER_MS = 2000;
/** After a PING, dead when nothing answers within this long (down within 5 s, issue 15). */
export const DEAD_AFTER_MS = 2500;
/** From connecting to the full model. */
export const FIRST_MODEL_MS = 6000;
/**
 * The DSF refused the credentials that are not this page's (the machine's configured password, or
 * none): why, what to do, and that it is tried again on its own.
 */
export const PASSWORD_REFUSED =
  'The Duet refused the password (HTTP 403): check this machine\'s "password" in the machines file, or log in here. It is tried again on its own, at most once a minute.';
export const NOOP_EVERY_MS = 4000;
/** While the socket cannot be opened, the object model is polled this often (`GET /machine/model`). */
export const POLL_EVERY_MS = 2000;
/** Polling starts only when the socket has been down this long (a quick reconnect needs none). */
export const POLL_AFTER_MS = 5000;
/** While the model is polled, no good answer for this long (two polls and slack) is the link down. */
export const POLL_SILENT_MS = 4500;
/** After a dropped frame a new socket reads the full model, at most this often (no socket churn). */
export const RESYNC_EVERY_MS = 10_000;
/**
 * A standalone board (`rr_*`): the model is polled this often (one session serves every viewer;
 * a board has few HTTP connections). It also keeps the session, which RRF drops after 8 s.
 */
export const RRF_POLL_MS = 1000;
/** A standalone board shown only on a tile (no page of it open): `rr_model` at the tile's pace. */
export const RRF_TILE_POLL_MS = 2000;
/**
 * Shown only on a tile, the `OK` that asks for the next patch waits until this long after the
 * last one (the sender then sends one patch with every change: nothing lost, and an idle fleet
 * page is not woken four times a second per printer). On the machine's page: at once.
 */
export const TILE_ACK_MS = 1000;
