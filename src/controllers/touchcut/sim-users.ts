/**
 * The simulated TouchCut's users, as data: the simulator (`sim/simulator.ts`, Node) logs them in,
 * and the login form of a simulated machine lists them. No simulator code here, so the browser
 * can import it (the production bundle carries no simulator).
 */

export interface SimUser {
  username: string;
  password: string;
  group: string;
}

/** Simulated users (the login form of a simulated machine lists them). */
export function defaultUsers(): SimUser[] {
  return [
    { username: 'admin', password: 'admin', group: 'Administrator' },
    { username: 'operator', password: 'operator', group: 'User' },
    { username: 'viewer', password: 'viewer', group: 'Monitor' },
    { username: 'office', password: 'office', group: 'Office' },
    { username: 'guest', password: 'guest', group: 'Guest' },
  ];
}
