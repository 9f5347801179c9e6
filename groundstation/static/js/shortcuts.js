// Keyboard shortcuts and the "?" help overlay that lists them (only keys the UI handles). The break-in
// joystick's keys are handled in joystick.js and listed here; a key typed into a text box is the box's.
const TYPING = ["INPUT", "SELECT", "TEXTAREA"];

/** ``onLayout()`` is called after the side panel is shown or hidden (the map re-measures itself). */
export function installShortcuts(onLayout) {
  const help = document.getElementById("help");
  const toggleHelp = () => { if (help.open) help.close(); else help.showModal(); };
  const togglePanel = () => {
    const hidden = document.body.classList.toggle("panel-hidden");
    document.getElementById("panel-toggle").setAttribute("aria-expanded", String(!hidden));
    onLayout();
  };
  document.getElementById("help-button").addEventListener("click", toggleHelp);
  document.getElementById("help-close").addEventListener("click", () => help.close());
  document.getElementById("panel-toggle").addEventListener("click", togglePanel);
  window.addEventListener("keydown", (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey || (e.target && TYPING.includes(e.target.tagName))) return;
    if (e.key === "?") { e.preventDefault(); toggleHelp(); }
    else if (e.key === "m" || e.key === "M") { e.preventDefault(); togglePanel(); }
  });
}
