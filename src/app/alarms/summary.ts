import { createStore } from 'zustand/vanilla';

/**
 * What the shell needs of the alarm centre before its code has loaded (the alarm layer is a chunk
 * of its own, loaded once the first screen shows): how many alarms block the page (App makes it
 * inert) and how many are unacknowledged (the navigation's count). The layer keeps it current.
 */
export const alarmSummary = createStore<{ blocking: number; unacknowledged: number }>(() => ({
  blocking: 0,
  unacknowledged: 0,
}));
